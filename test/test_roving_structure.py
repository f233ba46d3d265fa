"""Structure files with roving sensors (docs/interfaces.md §8): frame, roving, measurement_points."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

from shm_ros.core.structure import StructureError, structure_from_dict
from shm_ros.io.structure import dump_structure, load_structure

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "girder_roving.yaml"


def _data() -> dict:
    return yaml.safe_load(EXAMPLE.read_text())


def test_roving_example_loads_and_round_trips(tmp_path):
    spec = load_structure(EXAMPLE)
    assert spec.frame == "structure"
    assert [s.id for s in spec.sensors] == ["s_ref1", "s_ref2"]
    (r,) = spec.roving
    assert (r.id, r.frame, r.direction) == ("r1", "rover/accel_link", "vertical")
    assert r.mount is not None and r.mount.parent == "rover/base_link"
    # rpy 20 deg about y: quaternion (0, sin 10 deg, 0, cos 10 deg)
    np.testing.assert_allclose(r.mount.rotation, [0, np.sin(np.radians(10)), 0, np.cos(np.radians(10))],
                               atol=1e-12)
    assert len(spec.measurement_points) == 12
    assert spec.measurement_points[0].position == (3.5, 0.0, 0.0)
    out = tmp_path / "r.yaml"
    dump_structure(spec, out)
    again = load_structure(out)
    assert again.roving == spec.roving and again.measurement_points == spec.measurement_points


@pytest.mark.parametrize(("edit", "field", "words"), [
    (lambda d: d["sensors"][2].update(at={"x": 3.0}), "sensors[2].at", "takes no 'at'"),
    (lambda d: d["sensors"][2].pop("frame"), "sensors[2].frame", "missing required field"),
    (lambda d: d["sensors"][0].update(frame="a"), "sensors[0].frame", "only a roving sensor"),
    (lambda d: d["sensors"][2].update(roving="yes"), "sensors[2].roving", "true or false"),
    (lambda d: d.pop("measurement_points"), "measurement_points", "need measurement_points"),
    (lambda d: d["measurement_points"][3].update(at={"x": 99.0}), "measurement_points[3].at.x", "outside"),
    (lambda d: d["measurement_points"][1].update(id="s_ref1"), "measurement_points[1].id", "fixed sensor"),
    (lambda d: d["measurement_points"][1].update(id="p01"), "measurement_points[1].id", "another"),
    (lambda d: d["sensors"][2]["mount"].update(rotation=[0, 0, 0, 2]), "sensors[2].mount",
     "rotation"),
    (lambda d: d["sensors"][2]["mount"].update(translation=[0, 1]), "sensors[2].mount.translation", "3 numbers"),
    (lambda d: d.update(frame=""), "frame", "non-empty"),
    (lambda d: d["sensors"][2].update(carrier_mass_kg=-5.0), "sensors[2].carrier_mass_kg", ""),
    (lambda d: d.update(sensors=[d["sensors"][2]]), "sensors", "fixed sensor"),
])
def test_roving_errors_name_the_field(edit, field, words):
    d = copy.deepcopy(_data())
    edit(d)
    with pytest.raises(StructureError) as exc:
        structure_from_dict(d, source="rov.yaml")
    msg = str(exc.value)
    assert msg.startswith(f"rov.yaml: field '{field}") and words in msg, msg


def test_points_without_roving_sensor_refused():
    d = _data()
    d["sensors"] = d["sensors"][:2]
    with pytest.raises(StructureError, match="no sensor is roving"):
        structure_from_dict(d, source="rov.yaml")


def test_carrier_mass_round_trips(tmp_path):
    d = copy.deepcopy(_data())
    d["sensors"][2]["carrier_mass_kg"] = 2000.0
    spec = structure_from_dict(d)
    assert spec.roving[0].carrier_mass_kg == 2000.0
    dump_structure(spec, tmp_path / "s.yaml")
    assert load_structure(tmp_path / "s.yaml").roving[0].carrier_mass_kg == 2000.0
    assert structure_from_dict(copy.deepcopy(_data())).roving[0].carrier_mass_kg is None


def test_building_points_are_floors():
    d = yaml.safe_load((EXAMPLE.parent / "building.yaml").read_text())
    d["sensors"].append({"id": "d1", "roving": True, "frame": "drone/imu", "direction": "x"})
    d["measurement_points"] = [{"id": f"f{k}p", "at": {"floor": k}} for k in (1, 2, 3)]
    with pytest.raises(StructureError, match=r"measurement_points\[0\].xyz'.*needs xyz"):
        structure_from_dict(d)
    for k, p in enumerate(d["measurement_points"]):
        p["xyz"] = [1.0, 2.0, [3.2, 6.4, 9.6][k]]
    spec = structure_from_dict(d)
    assert [p.position for p in spec.measurement_points] == [(1.0, 2.0, 3.2), (1.0, 2.0, 6.4), (1.0, 2.0, 9.6)]
    assert spec.measurement_points[0].axes == (True, True, True)
