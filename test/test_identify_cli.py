"""`shm-ros identify`: bag -> modes.json (docs/interfaces.md §3) and stabilization plots."""

from __future__ import annotations

import json

import numpy as np
import pytest

import synthetic_oma as so
from shm_ros.cli import main
from shm_ros.io.bags import BagWriter

STRUCTURE = """\
name: twelve-floor-test
kind: shear_building
shear_building:
  floors:
{floors}
damping: {{kind: rayleigh, ratios: [0.02, 0.02]}}
sensors:
{sensors}
"""


@pytest.fixture(autouse=True)
def _one_blas_thread():
    with so.single_blas_thread():
        yield


def _write_case(tmp_path, duration=300.0):
    y, fs, truth, names = so.ambient_record(7, duration=duration, fs=40.0, noise=0.02)
    floors = "\n".join("    - {mass: 4.0e+5, stiffness: 6.0e+9}" for _ in range(12))
    sensors = "\n".join(f"  - {{id: {n}, at: {{floor: {int(n[1:])}}}, direction: x}}" for n in names)
    s = tmp_path / "s.yaml"
    s.write_text(STRUCTURE.format(floors=floors, sensors=sensors))
    bag = tmp_path / "rec"
    t0 = 1_714_521_600_000_000_000  # 2024-05-01T00:00:00Z
    block = 400
    with BagWriter(bag) as w:
        for k in range(0, y.shape[0], block):
            w.accel_block("/daq/accel_block", t0 + int(round(k / fs * 1e9)), fs, names,
                          np.asarray(y[k:k + block]))
    return s, bag, truth, names


def test_identify_cli_writes_modes_json_and_plots(tmp_path):
    s, bag, truth, names = _write_case(tmp_path)
    out = tmp_path / "modes.json"
    plots = tmp_path / "plots"
    rc = main(["identify", str(bag), "--structure", str(s), "--out", str(out), "--window", "150",
               "--plots", str(plots)])
    assert rc == 0
    doc = json.loads(out.read_text())
    assert "schema_version" in doc and "provenance" in doc
    assert len(doc["windows"]) == 2
    assert doc["windows"][0]["start"].startswith("2024-05-01T00:00:00")
    for rec in doc["windows"]:
        assert {"start", "end", "temperature_c", "modes"} <= set(rec)
        f = [m["frequency_hz"] for m in rec["modes"]]
        assert f == sorted(f) and len(f) >= 3
        # the first three truth modes are found within 1 % in each 150 s window
        for t in truth.frequency_hz[:3]:
            assert min(abs(x - t) / t for x in f) < 0.01
        for m in rec["modes"]:
            assert set(m["mode_shape"]) == set(names)
            assert max(abs(v) for v in m["mode_shape"].values()) == pytest.approx(1.0)
            assert max(m["mode_shape"].values()) == pytest.approx(1.0)
            assert 0 < m["damping_ratio"] <= 0.2 and 0 <= m["mpc"] <= 1
    assert len(list(plots.glob("*.png"))) == 2


def test_identify_cli_errors_are_clear(tmp_path, capsys):
    s, bag, _, _ = _write_case(tmp_path, duration=60.0)
    rc = main(["identify", str(bag), "--structure", str(s), "--out", str(tmp_path / "m.json"),
               "--method", "ssi-io"])
    assert rc == 2 and "input" in capsys.readouterr().err
    bad = tmp_path / "cfg.yaml"
    bad.write_text("stability: {freq_tol: 0.01, nonsense: 3}\n")
    rc = main(["identify", str(bag), "--structure", str(s), "--out", str(tmp_path / "m.json"),
               "--config", str(bad)])
    err = capsys.readouterr().err
    assert rc == 2 and "cfg.yaml" in err and "nonsense" in err


def test_identify_cli_ssi_data_weighting_reaches_the_configuration(tmp_path, capsys):
    s, bag, truth, _ = _write_case(tmp_path, duration=150.0)
    runs = {}
    for weighting in ("upc", "pc"):
        out = tmp_path / f"{weighting}.json"
        rc = main(["identify", str(bag), "--structure", str(s), "--out", str(out), "--window", "150",
                   "--method", "ssi-data", "--weighting", weighting, "--no-uncertainty"])
        assert rc == 0
        doc = json.loads(out.read_text())
        assert doc["provenance"]["configuration"]["identify"]["weighting"] == weighting
        runs[weighting] = [m["frequency_hz"] for m in doc["windows"][0]["modes"]]
        assert min(abs(x - truth.frequency_hz[0]) / truth.frequency_hz[0]
                   for x in runs[weighting]) < 0.01
    assert runs["upc"] != runs["pc"]  # a different subspace, not the same computation twice
    bad = tmp_path / "cfg.yaml"
    bad.write_text("weighting: pca\n")
    rc = main(["identify", str(bag), "--structure", str(s), "--out", str(tmp_path / "m.json"),
               "--method", "ssi-data", "--config", str(bad)])
    assert rc == 2 and "weighting" in capsys.readouterr().err
