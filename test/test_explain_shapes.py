"""Shapes as the second witness of tied candidates (shm_ros/core/explain/shapes.py).

On the symmetric three-span girder a stiffness loss in the first or the last span moves every
frequency alike; its shapes are mirror images. With the identified shapes of a loss in the first span
(scatter 2 % per component), the first span's candidate must be preferred by a wide margin; changes
of the whole mass, which change no shape, must stay level whatever their size."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from shm_ros.core.explain.config import ExplainConfig
from shm_ros.core.explain.groups import build_groups
from shm_ros.core.explain.shapes import predicted_shapes, shape_log_likelihood
from shm_ros.core.explain.surrogate import Surrogate
from shm_ros.core.simulate.scenario import GIRDER_STRUCTURE
from shm_ros.core.structure import structure_from_dict

W = 200

# the evidence check, prior sensitivity and surrogate check do not change what is named or fitted
FAST = ExplainConfig(nested_check=False, prior_sensitivity=False, surrogate_check=False)


@pytest.fixture(scope="module")
def girder():
    spec = structure_from_dict(copy.deepcopy(GIRDER_STRUCTURE))
    gm = build_groups(spec, {})
    sur = Surrogate(gm, [0, 1, 2, 3])
    S = gm.model.sensor_matrix([s.id for s in spec.sensors])
    return sur, S


def _step(size: float) -> np.ndarray:
    return np.where(np.arange(W) >= W // 2, 1.0 + size, 1.0)


def test_no_change_gives_the_baseline_shapes(girder):
    sur, S = girder
    got = predicted_shapes(sur, {"EI": np.ones(W)}, S)
    want = (S @ sur.phi_base[:, sur.model_index]).T
    assert got.shape == (W, 4, S.shape[0])
    assert np.allclose(np.abs(got[0]), np.abs(want), rtol=1e-8, atol=1e-12)


def test_mirror_spans_told_apart_by_their_shapes(girder):
    sur, S = girder
    rng = np.random.default_rng(3)
    truth = predicted_shapes(sur, {"EI:1": _step(-0.1)}, S)
    scale = np.sqrt(np.mean(truth ** 2, axis=2, keepdims=True))
    observed = truth + 0.02 * scale * rng.standard_normal(truth.shape)
    observed[rng.random(observed.shape) < 0.02] = np.nan  # a few components not identified
    train = np.arange(W) % 4 != 3
    f1 = sur.delta(_mod("EI:1", _step(-0.1)))
    f3 = sur.delta(_mod("EI:3", _step(-0.1)))
    assert np.allclose(f1, f3, atol=1e-6)  # the frequencies cannot tell the spans apart
    ll1 = shape_log_likelihood(observed, truth, train)
    ll3 = shape_log_likelihood(observed, predicted_shapes(sur, {"EI:3": _step(-0.1)}, S), train)
    assert ll1 - ll3 > 50.0, (ll1, ll3)
    # the whole mass scaled: no shape moves, level whatever the size
    la = shape_log_likelihood(observed, predicted_shapes(sur, {"mass": _step(0.02)}, S), train)
    lb = shape_log_likelihood(observed, predicted_shapes(sur, {"mass": _step(0.08)}, S), train)
    assert abs(la - lb) < 1e-4 and la < ll1


def _mod(group: str, x: np.ndarray):
    from shm_ros.core.explain.candidates.base import Modification

    return Modification({group: x[None]})


def test_whole_structure_groups_stay_level_among_themselves():
    from shm_ros.core.explain.shapes import shape_terms

    ll = {"step/EI": -10.0, "added_mass/mass": 30.0, "step/EI:1": 5.0, "added_mass/mass:3": 50.0}
    where = {"step/EI": "EI", "added_mass/mass": "mass", "step/EI:1": "EI:1", "added_mass/mass:3": "mass:3"}
    t = shape_terms(ll, where)
    assert t["step/EI"] == t["added_mass/mass"] == 30.0
    assert t["step/EI:1"] == 5.0 and t["added_mass/mass:3"] == 50.0


def test_candidates_on_one_group_share_its_best_shape_term():
    """Two forms of a change of the same group (a frost knee and a temperature knee of the bearings)
    are not told apart by shapes; candidates on other groups keep their own terms."""
    from shm_ros.core.explain.shapes import shape_terms

    ll = {"support_springs/bearings": -44.0, "temperature_bilinear/bearings": 0.0, "step/EI:2": -3.0,
          "step/EI:1": -60.0}
    where = {k: k.split("/")[1] for k in ll}
    t = shape_terms(ll, where)
    assert t["support_springs/bearings"] == t["temperature_bilinear/bearings"] == 0.0
    assert t["step/EI:2"] == -3.0 and t["step/EI:1"] == -60.0


def test_explain_names_the_span_not_its_mirror():
    """End to end (test/explain_cases.py, 192 windows): a stiffness loss in span 3 of the girder ties
    with span 1 on frequencies; the verdict names span 3 alone, span 1 out by its shapes."""
    from explain_cases import draw_case

    from shm_ros.core.explain.explain import explain

    case = draw_case(30009, "stiffness_change_at_time", n_windows=192)
    assert case.kind == "girder" and case.truth.where == "EI:3"
    d = explain(case.obs, structure_from_dict(case.structure), FAST).to_dict()
    top = next(m for m in d["missing_physics"] if m["name"] != "unmodelled_modes")
    assert top["name"] == "stiffness_change_at_time" and top["where"] == "EI:3" and not top.get("tied_with"), top
    mirror = [c for c in d["candidates"] if c["label"] == "stiffness_change_at_time/step/EI:1"]
    assert mirror and not mirror[0]["accepted"], mirror
    assert any("identified shapes" in r for r in mirror[0]["reasons"]), mirror[0]["reasons"]


def test_second_round_takes_the_span_the_shapes_name():
    """Two effects (a knee on the whole deck, then a loss in span 3; 192 windows): on top of the knee
    the loss in span 1 and in span 3 gain the same to 0.1 nats; the shapes choose span 3."""
    from explain_cases import draw_case

    from shm_ros.core.explain.explain import explain

    case = draw_case(9010, "temperature_dependent_stiffness", kind="girder", n_windows=192, form="bilinear",
                     second_step=True)
    assert case.truth.second is not None and case.truth.second.where == "EI:3"
    d = explain(case.obs, structure_from_dict(case.structure), FAST).to_dict()
    step = [m for m in d["missing_physics"] if m["name"] == "stiffness_change_at_time"]
    assert [m["where"] for m in step] == ["EI:3"], d["missing_physics"]
    mirror = [c for c in d["candidates"] if c["label"] == "stiffness_change_at_time/step/EI:1"
              and " on top of " in " ".join(c["reasons"])]
    assert mirror and not mirror[0]["accepted"] and mirror[0]["shape_log_likelihood"] < -100, mirror
    assert abs(mirror[0]["log_evidence_gain"] - step[0]["log_evidence_gain"]) < 2.0
