"""Structure files (docs/interfaces.md §2): loading, defaults, parameter paths, errors naming file+field."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

from shm_ros.core.models import build_model
from shm_ros.core.structure import StructureError, resolve_path, structure_from_dict
from shm_ros.io.structure import dump_structure, load_structure

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _building_dict() -> dict:
    return yaml.safe_load((EXAMPLES / "building.yaml").read_text())


def _girder_dict() -> dict:
    return yaml.safe_load((EXAMPLES / "girder.yaml").read_text())


def _write(tmp_path: Path, data: dict, name: str = "s.yaml") -> Path:
    p = tmp_path / name
    p.write_text(yaml.safe_dump(data, sort_keys=False))
    return p


@pytest.mark.parametrize("name", ["girder", "building", "matrices"])
def test_examples_load_build_and_round_trip(tmp_path, name):
    spec = load_structure(EXAMPLES / f"{name}.yaml")
    model = build_model(spec)
    f = model.modes(n_modes=3).frequencies_hz
    assert np.all(np.diff(f) > 0) and f[0] > 0
    out = tmp_path / f"{name}.yaml"
    dump_structure(spec, out)
    again = load_structure(out)
    assert again.to_dict() == spec.to_dict()
    np.testing.assert_allclose(build_model(again).modes(n_modes=3).frequencies_hz, f, rtol=1e-12)
    assert [p.name for p in again.parameters] == [p.name for p in spec.parameters]


def test_sensor_source_defaults_and_explicit():
    d = _building_dict()
    d["sensors"] += [
        {"id": "f8y", "at": {"floor": 8}, "direction": "y", "source": {"topic": "f8", "axis": "y", "sign": -1}},
        {"id": "f4", "at": {"floor": 4}, "direction": "x", "source": {"channel": "ch07"}},
    ]
    spec = structure_from_dict(d, source="b.yaml")
    s = spec.sensor("f8")
    assert (s.source.topic, s.source.axis, s.source.sign, s.source.channel) == ("f8", "x", 1.0, "f8")
    s = spec.sensor("f8y")
    assert (s.source.topic, s.source.axis, s.source.sign, s.source.channel) == ("f8", "y", -1.0, None)
    s = spec.sensor("f4")
    assert (s.source.topic, s.source.axis, s.source.sign, s.source.channel) == (None, "x", 1.0, "ch07")
    g = load_structure(EXAMPLES / "girder.yaml").sensor("s3")
    assert g.source.axis == "z" and g.x == 29.0
    assert spec.input_sensor == "g0" and spec.output_sensor_ids[0] == "f1"


def test_parameter_path_resolution():
    d = _building_dict()
    assert resolve_path(d, "shear_building.floors[0,1].stiffness") == [
        ("shear_building", "floors", 0, "stiffness"),
        ("shear_building", "floors", 1, "stiffness"),
    ]
    star = resolve_path(d, "shear_building.floors[*].mass")
    bare = resolve_path(d, "shear_building.floors.mass")
    assert star == bare == [("shear_building", "floors", i, "mass") for i in range(8)]
    assert resolve_path(d, "damping.ratios[1]") == [("damping", "ratios", 1)]
    g = _girder_dict()
    assert resolve_path(g, "girder.section.E") == [("girder", "section", "E")]
    assert len(resolve_path(g, "girder.bearings.k_vertical")) == 4
    g["girder"]["section"] = [dict(g["girder"]["section"]) for _ in range(3)]
    assert resolve_path(g, "girder.section[1,2].I") == [("girder", "section", 1, "I"), ("girder", "section", 2, "I")]
    assert len(resolve_path(g, "girder.section.E")) == 3


def test_parameters_map_to_the_right_model_terms():
    """A factor theta on a path gives the same model as the file with those values multiplied."""
    d = _building_dict()
    d["parameters"] = [
        {"name": "k01", "applies_to": "shear_building.floors[0,1].stiffness", "prior": {"dist": "normal", "mean": 1, "std": 0.1}},
        {"name": "m_all", "applies_to": "shear_building.floors[*].mass", "prior": {"dist": "normal", "mean": 1, "std": 0.1}},
        {"name": "k7", "applies_to": "shear_building.floors[7].stiffness", "prior": {"dist": "normal", "mean": 1, "std": 0.1}},
    ]
    spec = structure_from_dict(d, source="b.yaml")
    model = build_model(spec)
    theta = np.array([0.8, 1.1, 1.3])
    ref = build_model(spec.scaled(dict(zip(model.parameter_names, theta))), include_parameters=False)
    np.testing.assert_allclose(model.stiffness(theta), ref.stiffness(), rtol=1e-12)
    np.testing.assert_allclose(model.mass(theta), ref.mass(), rtol=1e-12)
    assert not np.allclose(model.stiffness(theta), model.stiffness())

    g = _girder_dict()
    g["girder"]["section"] = [dict(g["girder"]["section"]) for _ in range(3)]
    g["parameters"] = [
        {"name": "E_mid", "applies_to": "girder.section[1].E", "prior": {"dist": "normal", "mean": 1, "std": 0.1}},
        {"name": "rho_all", "applies_to": "girder.section[*].rho", "prior": {"dist": "normal", "mean": 1, "std": 0.1}},
        {"name": "kv_ends", "applies_to": "girder.bearings[0,3].k_vertical", "prior": {"dist": "weibull", "scale": 1, "shape": 5}},
        {"name": "kr", "applies_to": "girder.bearings.k_rotation", "prior": {"dist": "uniform", "low": 0, "high": 2}},
        {"name": "zeta1", "applies_to": "damping.ratios[0]", "prior": {"dist": "lognormal", "mean": 1, "std": 0.3}},
    ]
    g["girder"]["bearings"][1]["k_rotation"] = 1.0e9
    spec = structure_from_dict(g, source="g.yaml")
    model = build_model(spec)
    theta = np.array([1.2, 0.9, 0.5, 1.7, 2.0])
    ref = build_model(spec.scaled(dict(zip(model.parameter_names, theta))), include_parameters=False)
    np.testing.assert_allclose(model.stiffness(theta), ref.stiffness(), rtol=1e-12, atol=1e-3)
    np.testing.assert_allclose(model.mass(theta), ref.mass(), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(model.damping_ratios_at(theta), [0.03, 0.015])
    # batched matrices agree with the single ones
    thetas = np.array([theta, np.ones(5), 0.7 * theta])
    for b in range(3):
        np.testing.assert_allclose(model.stiffness_batch(thetas)[b], model.stiffness(thetas[b]), rtol=1e-12, atol=1e-3)
        np.testing.assert_allclose(model.mass_batch(thetas)[b], model.mass(thetas[b]), rtol=1e-12)


def test_priors_are_of_the_factor_itself():
    d = _building_dict()
    d["parameters"][0]["prior"] = {"dist": "lognormal", "mean": 1.2, "std": 0.3}
    d["parameters"][1]["prior"] = {"dist": "weibull", "scale": 1.1, "shape": 8.0}
    spec = structure_from_dict(d, source="b.yaml")
    ln = spec.parameters[0].prior.frozen()
    assert ln.mean() == pytest.approx(1.2, rel=1e-12) and ln.std() == pytest.approx(0.3, rel=1e-12)
    wb = spec.parameters[1].prior.frozen()
    assert wb.cdf(1.1) == pytest.approx(1 - np.exp(-1.0))
    n = spec.parameters[2].prior.frozen()
    assert n.mean() == 1.0 and n.std() == 0.15


def _mutations():
    """(description, mutate(dict), expected field in the message)"""

    def setp(path, value):
        def f(d):
            node = d
            for k in path[:-1]:
                node = node[k]
            node[path[-1]] = value

        return f

    def delp(path):
        def f(d):
            node = d
            for k in path[:-1]:
                node = node[k]
            del node[path[-1]]

        return f

    return [
        ("unknown kind", setp(["kind"], "truss"), "'kind'"),
        ("unknown top field", setp(["colour"], "red"), "colour"),
        ("missing floors", delp(["shear_building", "floors"]), "shear_building.floors"),
        ("bad mass", setp(["shear_building", "floors", 2, "mass"], "heavy"), "shear_building.floors[2].mass"),
        ("negative stiffness", setp(["shear_building", "floors", 4, "stiffness"], -1.0), "shear_building.floors[4].stiffness"),
        ("unknown floor field", setp(["shear_building", "floors", 0, "heigth"], 3.0), "shear_building.floors[0].heigth"),
        ("negative height", setp(["shear_building", "floors", 3, "height"], -3.0), "shear_building.floors[3].height"),
        ("zero height", setp(["shear_building", "floors", 3, "height"], 0.0), "shear_building.floors[3].height"),
        ("damper out of range", setp(["shear_building", "dampers"], [{"between": [0, 1], "c": 1e6},
                                                                      {"between": [2, 9], "c": 1e6}]),
         "shear_building.dampers[1].between[1]"),
        ("damper negative end", setp(["shear_building", "dampers"], [{"between": [-1, 1], "c": 1e6}]),
         "shear_building.dampers[0].between[0]"),
        ("damper one floor", setp(["shear_building", "dampers"], [{"between": [3, 3], "c": 1e6}]),
         "shear_building.dampers[0].between"),
        ("damper three floors", setp(["shear_building", "dampers"], [{"between": [1, 2, 3], "c": 1e6}]),
         "shear_building.dampers[0].between"),
        ("damper unknown key", setp(["shear_building", "dampers"], [{"between": [0, 1], "c": 1e6, "k": 1.0}]),
         "shear_building.dampers[0].k"),
        ("damper negative c", setp(["shear_building", "dampers"], [{"between": [0, 1], "c": -1e6}]),
         "shear_building.dampers[0].c"),
        ("damper zero maxwell", setp(["shear_building", "dampers"], [{"between": [0, 1], "c": 1e6, "k_maxwell": 0}]),
         "shear_building.dampers[0].k_maxwell"),
        ("damper not updatable", setp(["parameters", 0, "applies_to"], "shear_building.dampers[0].c"),
         "parameters[0].applies_to"),
        ("input and inputs", setp(["inputs"], [{"sensor": "g0"}]), "'inputs'"),
        ("input unknown key", setp(["input"], {"sensor": "g0", "where": 1}), "input.where"),
        ("input unknown kind", setp(["input"], {"sensor": "g0", "kind": "wind"}), "input.kind"),
        ("base input on a floor", setp(["input"], {"sensor": "f3", "kind": "base"}), "input.kind"),
        ("base input with at", setp(["input"], {"sensor": "g0", "at": {"floor": 0}}), "input.at"),
        ("floor input at ground", setp(["input"], {"sensor": "g0", "kind": "floor"}), "input.at.floor"),
        ("force at missing floor", setp(["input"], {"sensor": "f3", "kind": "force", "at": {"floor": 9}}),
         "input.at.floor"),
        ("zero gain", setp(["input"], {"sensor": "f3", "kind": "force", "gain": 0}), "input.gain"),
        ("prior both lognormal forms", setp(["parameters", 2, "prior"],
                                            {"dist": "lognormal", "mean": 1, "std": 0.1, "mu_ln": 0.0}),
         "parameters[2].prior"),
        ("prior half log form", setp(["parameters", 2, "prior"], {"dist": "lognormal", "mu_ln": 0.0}),
         "parameters[2].prior.sigma_ln"),
        ("prior negative sigma_ln", setp(["parameters", 2, "prior"],
                                         {"dist": "lognormal", "mu_ln": 0.0, "sigma_ln": -0.1}),
         "parameters[2].prior.sigma_ln"),
        ("floor out of range", setp(["sensors", 2, "at"], {"floor": 12}), "sensors[2].at.floor"),
        ("bad direction", setp(["sensors", 1, "direction"], "up"), "sensors[1].direction"),
        ("bad axis", setp(["sensors", 1, "source"], {"axis": "w"}), "sensors[1].source.axis"),
        ("duplicate id", setp(["sensors", 3, "id"], "f1"), "sensors[3].id"),
        ("input not a sensor", setp(["input"], {"sensor": "nope"}), "input.sensor"),
        ("unknown path", setp(["parameters", 1, "applies_to"], "shear_building.floors[*].stifness"), "parameters[1].applies_to"),
        ("index out of range", setp(["parameters", 0, "applies_to"], "shear_building.floors[0,9].stiffness"), "parameters[0].applies_to"),
        ("bad index", setp(["parameters", 0, "applies_to"], "shear_building.floors[a].stiffness"), "parameters[0].applies_to"),
        ("not updatable", setp(["parameters", 0, "applies_to"], "sensors[0].at.floor"), "parameters[0].applies_to"),
        ("same term twice", setp(["parameters", 1, "applies_to"], "shear_building.floors[1].stiffness"), "parameters[1].applies_to"),
        ("unknown prior", setp(["parameters", 2, "prior"], {"dist": "cauchy", "loc": 1}), "parameters[2].prior.dist"),
        ("prior field missing", setp(["parameters", 2, "prior"], {"dist": "normal", "mean": 1}), "parameters[2].prior.std"),
        ("uniform inverted", setp(["parameters", 2, "prior"], {"dist": "uniform", "low": 2, "high": 1}), "parameters[2].prior.high"),
        ("rayleigh needs two", setp(["damping"], {"kind": "rayleigh", "ratios": [0.02]}), "damping.ratios"),
    ]


@pytest.mark.parametrize("desc,mutate,fld", _mutations(), ids=[m[0] for m in _mutations()])
def test_loading_errors_name_file_and_field(tmp_path, desc, mutate, fld):
    d = _building_dict()
    mutate(d)
    p = _write(tmp_path, d, "bad_building.yaml")
    with pytest.raises(StructureError) as e:
        load_structure(p)
    msg = str(e.value)
    assert "bad_building.yaml" in msg, msg
    assert fld in msg, msg


def test_girder_errors(tmp_path):
    cases = [
        (lambda d: d["girder"]["section"].pop("I"), "girder.section.I"),
        (lambda d: d["girder"].__setitem__("section", [d["girder"]["section"]] * 2), "girder.section"),
        (lambda d: d["girder"]["bearings"][2].__setitem__("x", 70.0), "girder.bearings[2].x"),
        (lambda d: d["sensors"][0]["at"].__setitem__("x", -3.0), "sensors[0].at.x"),
        (lambda d: d["sensors"][0].__setitem__("direction", "x"), "sensors[0].direction"),
        # E and I of the same span would multiply two factors: not affine
        (
            lambda d: d["parameters"].append(
                {"name": "I_scale", "applies_to": "girder.section.I", "prior": {"dist": "normal", "mean": 1, "std": 0.1}}
            ),
            "parameters[2].applies_to",
        ),
        (lambda d: d["parameters"][0].__setitem__("applies_to", "girder.spans[1]"), "parameters[0].applies_to"),
        (lambda d: d["parameters"][0].__setitem__("applies_to", "girder.section[0].E"), "parameters[0].applies_to"),
    ]
    for i, (mutate, fld) in enumerate(cases):
        d = copy.deepcopy(_girder_dict())
        mutate(d)
        p = _write(tmp_path, d, f"bad_girder_{i}.yaml")
        with pytest.raises(StructureError) as e:
            load_structure(p)
        assert f"bad_girder_{i}.yaml" in str(e.value) and fld in str(e.value), str(e.value)


def test_file_level_errors(tmp_path):
    with pytest.raises(StructureError, match="missing.yaml.*not found"):
        load_structure(tmp_path / "missing.yaml")
    p = tmp_path / "broken.yaml"
    p.write_text("name: [unclosed\n")
    with pytest.raises(StructureError, match="broken.yaml.*YAML"):
        load_structure(p)
    d = yaml.safe_load((EXAMPLES / "matrices.yaml").read_text())
    d["matrices"]["file"] = "nowhere.npz"
    with pytest.raises(StructureError, match=r"m1.yaml.*matrices\.file.*nowhere\.npz"):
        load_structure(_write(tmp_path, d, "m1.yaml"))
    arrays = dict(np.load(EXAMPLES / "matrices.npz"))
    arrays["K_upper"] = arrays["K_upper"] + np.triu(np.ones((6, 6)), 1)
    np.savez(tmp_path / "asym.npz", **arrays)
    d["matrices"]["file"] = "asym.npz"
    with pytest.raises(StructureError, match=r"m2.yaml.*matrices\.terms\.K_upper.*not symmetric"):
        load_structure(_write(tmp_path, d, "m2.yaml"))
    singular = dict(arrays, K_upper=arrays["K_upper"] - np.triu(np.ones((6, 6)), 1), M=np.diag([1.0, 1, 1, 1, 1, 0]))
    np.savez(tmp_path / "massless.npz", **singular)
    d["matrices"]["file"] = "massless.npz"
    with pytest.raises(StructureError, match=r"m4.yaml.*matrices\.mass.*positive definite"):
        load_structure(_write(tmp_path, d, "m4.yaml"))
    del arrays["K_upper"]
    np.savez(tmp_path / "short.npz", **arrays)
    d["matrices"]["file"] = "short.npz"
    with pytest.raises(StructureError, match=r"m3.yaml.*matrices\.terms\.K_upper.*not found"):
        load_structure(_write(tmp_path, d, "m3.yaml"))


CONTRACT_EXAMPLE = """
name: deokpyeong-like-girder
kind: girder            # girder | shear_building | matrices
girder:                 # 2-D Euler-Bernoulli beam on bearings
  spans: [14.0, 30.0, 14.0]          # m
  elements_per_span: 10
  section: {E: 3.4e10, I: 2.1, A: 5.2, rho: 2500}   # or a list, one per span
  bearings:                          # one per support, x in m from the left end
    - {x: 0.0,  k_vertical: 5.0e9, k_rotation: 0.0}
    - {x: 14.0, k_vertical: 5.0e9, k_rotation: 0.0}
    - {x: 44.0, k_vertical: 5.0e9, k_rotation: 0.0}
    - {x: 58.0, k_vertical: 5.0e9, k_rotation: 0.0}
shear_building:                      # used instead of girder when kind: shear_building
  floors:                            # bottom up; stiffness = story below the floor
    - {mass: 4.0e5, stiffness: 6.0e8}
damping: {kind: rayleigh, ratios: [0.02, 0.02]}     # or {kind: modal, ratios: [...]}
sensors:
  - {id: s1, at: {x: 7.0}, direction: vertical}
parameters:
  - name: E_scale
    applies_to: girder.section.E     # multiplicative factor on the nominal value
    prior: {dist: normal, mean: 1.0, std: 0.1}
"""


def test_interfaces_example_loads(tmp_path):
    """A girder in the documented form (docs/interfaces.md §2; YAML 1.1 reads 3.4e10 as text, it is
    still a number), with the unused shear_building section ignored."""
    p = tmp_path / "interfaces_example.yaml"
    p.write_text(CONTRACT_EXAMPLE)
    spec = load_structure(p)
    assert spec.girder.sections[0].E == 3.4e10 and spec.girder.bearings[1].k_vertical == 5.0e9
    assert spec.shear_building is None and "shear_building" in spec.raw
    model = build_model(spec)
    assert model.parameter_names == ["E_scale"] and model.sensor_dofs["s1"] % 2 == 0
    d = yaml.safe_load(CONTRACT_EXAMPLE)
    del d["parameters"][0]["prior"]
    with pytest.raises(StructureError, match=r"parameters\[0\]\.prior"):
        structure_from_dict(d, "noprior.yaml")


def test_typed_edits_survive_to_dict():
    """Editing the typed spec (as a truth-model builder does) is kept by to_dict / scaled."""
    spec = load_structure(EXAMPLES / "girder.yaml")
    spec.girder.sections[1].E *= 0.5
    d = spec.to_dict()
    assert isinstance(d["girder"]["section"], list) and d["girder"]["section"][1]["E"] == 1.7e10
    again = structure_from_dict(d, "edited.yaml")
    assert again.girder.sections[1].E == 1.7e10 and again.girder.sections[0].E == 3.4e10
    s2 = spec.scaled({"bearing_kv_scale": 0.5})
    assert s2.girder.sections[1].E == 1.7e10 and s2.girder.bearings[2].k_vertical == 2.5e9


def test_duplicate_yaml_key_is_an_error(tmp_path):
    p = tmp_path / "dup.yaml"
    p.write_text((EXAMPLES / "building.yaml").read_text().replace("damping: {", "damping: {kind: modal, ", 1))
    with pytest.raises(StructureError, match=r"(?s)dup.yaml.*'kind' appears twice.*line 16"):
        load_structure(p)


def test_lognormal_log_space_form_equals_factor_form():
    d = _building_dict()
    d["parameters"][0]["prior"] = {"dist": "lognormal", "mean": 1.1, "std": 0.2}
    s2 = np.log1p((0.2 / 1.1) ** 2)
    d["parameters"][1]["prior"] = {"dist": "lognormal", "mu_ln": float(np.log(1.1) - s2 / 2),
                                   "sigma_ln": float(np.sqrt(s2))}
    spec = structure_from_dict(d, source="b.yaml")
    a, b = spec.parameters[0].prior.frozen(), spec.parameters[1].prior.frozen()
    x = np.linspace(0.5, 2.0, 31)
    np.testing.assert_allclose(a.logpdf(x), b.logpdf(x), rtol=1e-12)
    assert b.mean() == pytest.approx(1.1, rel=1e-12) and b.std() == pytest.approx(0.2, rel=1e-12)
    assert spec.parameters[1].prior.params == {"mu_ln": pytest.approx(np.log(1.1) - s2 / 2),
                                               "sigma_ln": pytest.approx(np.sqrt(s2))}


def test_input_kinds_defaults_and_round_trip(tmp_path):
    d = _building_dict()
    spec = structure_from_dict(d, source="b.yaml")
    assert [(i.sensor, i.kind, i.gain) for i in spec.inputs] == [("g0", "base", 1.0)]
    # a sensor on a floor records that floor's motion: kind floor by default, not ground motion
    d["input"] = {"sensor": "f3"}
    spec = structure_from_dict(d, source="b.yaml")
    assert spec.inputs[0].kind == "floor" and spec.inputs[0].at == {"floor": 3}
    assert spec.input_sensor == "f3" and "f3" not in spec.output_sensor_ids
    # several inputs, heights and dampers survive dump and load
    del d["input"]
    d["sensors"].append({"id": "shaker", "at": {"floor": 8}, "direction": "x"})
    d["inputs"] = [{"sensor": "g0"}, {"sensor": "f3", "kind": "floor", "gain": 9.81},
                   {"sensor": "shaker", "kind": "force", "at": {"floor": 7}, "gain": 2.5e3}]
    for i, f in enumerate(d["shear_building"]["floors"]):
        f["height"] = 4.5 if i == 0 else 3.5
    d["shear_building"]["dampers"] = [{"between": [0, 1], "c": 2.0e6},
                                      {"between": [2, 4], "c": 1.0e6, "k_maxwell": 3.0e7}]
    spec = structure_from_dict(d, source="b.yaml")
    assert spec.input_sensor_ids() == ["g0", "f3", "shaker"]
    assert [i.kind for i in spec.inputs] == ["base", "floor", "force"]
    assert spec.inputs[2].at == {"floor": 7} and spec.inputs[2].gain == 2.5e3
    assert spec.output_sensor_ids == ["f1", "f6", "f8"]
    assert spec.shear_building.floors[0].height == 4.5
    assert spec.shear_building.dampers[1].between == (2, 4) and spec.shear_building.dampers[1].k_maxwell == 3.0e7
    out = tmp_path / "again.yaml"
    dump_structure(spec, out)
    again = load_structure(out)
    assert again.to_dict() == spec.to_dict()
    assert again.inputs == spec.inputs and again.shear_building == spec.shear_building
    model = build_model(again)
    assert model.story_heights is not None
    np.testing.assert_allclose(model.story_heights, np.array([4.5] + [3.5] * 7))
    assert [dm.nodes for dm in model.dampers] == [(None, 0), (1, 3)]
    assert [i.sensor for i in model.inputs] == ["g0", "f3", "shaker"]


def test_dampers_make_damping_non_classical():
    d = _building_dict()
    base = build_model(structure_from_dict(d, source="b.yaml"))
    d["shear_building"]["dampers"] = [{"between": [0, 1], "c": 5.0e6},
                                      {"between": [1, 3], "c": 2.0e6},
                                      {"between": [3, 4], "c": 1.0e6, "k_maxwell": 1.0e8}]
    model = build_model(structure_from_dict(d, source="b.yaml"))
    dC = model.damping() - base.damping()
    expected = np.zeros((8, 8))
    expected[0, 0] += 5.0e6
    expected[np.ix_([0, 2], [0, 2])] += 2.0e6 * np.array([[1, -1], [-1, 1]])
    np.testing.assert_allclose(dC, expected, atol=1e-6)  # the Maxwell dashpot is not in C
    phi = model.modes(n_modes=8).shapes
    modal_C = phi.T @ model.damping() @ phi
    off = modal_C - np.diag(np.diag(modal_C))
    assert np.max(np.abs(off)) > 0.05 * np.max(np.abs(np.diag(modal_C)))  # not diagonal: non-classical
