"""The explain engine end to end on the simulator's truth (outside the analysis model's class).

Two tables from :mod:`explain_engine_synth` at reduced size (192 ten-minute windows, 32 h): one with
the simulator's ``temperature_bilinear`` effect on the deck (knee 0 degC, -0.2 %/degC above,
-5.2 %/degC below), one clean. The multi-seed statistics of the acceptance criteria (>= 40 random
cases, >= 50 clean seeds) run in bench/calibrate_explain.py and on xlocate's case generator; here one
seed each checks that the chain can name the effect and stays silent without one.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))

from explain_engine_synth import engine_table  # noqa: E402

from shm_ros.core.explain.config import ExplainConfig  # noqa: E402
from shm_ros.core.explain.explain import explain, split  # noqa: E402
from shm_ros.core.explain.select import shipped_threshold  # noqa: E402
from shm_ros.core.explain.timedomain import TD_CANDIDATES  # noqa: E402

N_WINDOWS = 192


@pytest.fixture(scope="module")
def bilinear_verdict():
    obs, spec, truth = engine_table(3, N_WINDOWS, ("temperature_bilinear", {}))
    return explain(obs, spec, ExplainConfig(n_importance=2000)), truth


def test_names_the_bilinear_temperature_effect(bilinear_verdict):
    v, truth = bilinear_verdict
    top = v.missing_physics[0]
    assert top.name == "temperature_dependent_stiffness"
    assert top.label.split("/")[1] == "temperature_bilinear"
    knee = truth["effect"]["parameters"]["knee_c"]
    assert abs(top.parameters["knee_c"] - knee) <= 1.5
    below = truth["effect"]["parameters"]["below_per_c"]
    assert abs(top.parameters["below_per_c"] - below) <= 0.25 * abs(below)
    # the fit improves: RMSE at least halved, on the held-out windows too
    assert v.fit_after.frequency_rmse_pct <= 0.5 * v.fit_before.frequency_rmse_pct
    assert v.held_out_after.frequency_rmse_pct < v.held_out_before.frequency_rmse_pct
    # the key parameter's interval excludes the null, the threshold is cleared, the check agrees
    lo, hi = top.intervals["below_per_c"]
    assert hi < 0.0
    assert top.log_evidence_gain > v.threshold["log_bayes_factor"]
    assert top.log_evidence_gain_check is not None
    tol = max(0.5, 3 * np.hypot(top.log_evidence_gain_err, top.extra["check_err"]))
    assert abs(top.log_evidence_gain_check - top.log_evidence_gain) <= tol
    assert set(top.prior_sensitivity) == {"halved", "doubled"}
    assert top.extra["surrogate_error"] < 1e-4
    assert v.unexplained is None


def test_verdict_is_serialisable(bilinear_verdict):
    import json

    v, _ = bilinear_verdict
    d = json.loads(json.dumps(v.to_dict()))
    assert d["missing_physics"][0]["name"] == "temperature_dependent_stiffness"
    assert d["fit"]["held_out"]["after"]["frequency_rmse_pct"] < d["fit"]["held_out"]["before"]["frequency_rmse_pct"]
    assert len(d["candidates"]) == len(v.tried) >= 3
    # is what remains noise? Before, every mode's misfit follows the temperature (lag-1 about 0.97);
    # the knee takes most of it (the truth's knee moves the modes in other proportions than the model's)
    w = d["fit"]["residual_whiteness"]
    assert min(w["lag1_before"]) > 0.9 and max(w["ljung_box_p_before"]) < 1e-3, w
    assert all(a < b - 0.3 for a, b in zip(w["lag1_after"], w["lag1_before"], strict=True)), w


def test_clean_table_raises_no_alarm():
    obs, spec, _ = engine_table(4, N_WINDOWS, None)
    v = explain(obs, spec, ExplainConfig(n_importance=1000, prior_sensitivity=False))
    physics = [c for c in v.missing_physics if c.name != "unmodelled_modes"]
    assert physics == [], [(c.label, c.log_evidence_gain) for c in physics]
    assert v.unexplained is None
    assert max((c.log_evidence_gain for c in v.tried), default=-np.inf) < v.threshold["log_bayes_factor"]
    assert v.whiteness is not None and v.whiteness.still_structured == [] and v.whiteness.note() is None


def test_held_out_blocks_and_threshold_file():
    t = np.arange(8 * 144) * 600.0
    train = split(t, ExplainConfig())
    assert 0.7 < train.mean() < 0.8  # every 4th block (a third of a day) held out
    assert not train[3 * 48:4 * 48].any() and train[:3 * 48].all() and train[4 * 48:7 * 48].all()
    th = shipped_threshold()
    assert th["log_bayes_factor"] > 0 and "command" in th


def test_time_domain_threshold_is_its_calibration():
    """The shipped time-domain threshold is the 99th percentile of the clean replicates it records
    (``test/td_threshold.py``), from at least 100 of them, and few of them exceed it."""
    th = shipped_threshold("threshold_timedomain.json")
    g = np.array(th["gains"])
    assert th["replicates"] == g.size >= 100 and not th["provisional"]
    assert th["log_bayes_factor"] == pytest.approx(max(round(float(np.quantile(g, 0.99)), 2), 0.0), abs=0.01)
    assert np.mean(g > th["log_bayes_factor"]) <= 0.02 and "td_threshold.py" in th["command"]
    for ext in th.get("extended", []):  # a candidate added later: its gains on the same replicates count
        assert len(ext["gains"]) == g.size and np.all(g >= np.array(ext["gains"]) - 0.01)
    assert set(TD_CANDIDATES) <= set(th["candidates"])  # calibrated on the candidate set explain tries


def test_a_second_effect_with_the_first_ones_course_in_time_is_not_a_second_effect():
    """A knee on the mirror span on top of a knee (the bench's spurious second effect, 146 nats at
    1,152 windows: correlation 0.97 of the two courses) is one effect moving the modes in other
    proportions than the model's; a later step or a rush-hour mass (correlation ~0.1) is another."""
    from shm_ros.core.explain.candidates import CANDIDATES, Context
    from shm_ros.core.explain.rounds import SAME_COURSE, _same_course, time_course

    rng = np.random.default_rng(5)
    W = 576
    times = np.arange(W) * 600.0
    temp = 5.0 + 8.0 * np.sin(2 * np.pi * times / 86400.0) + np.cumsum(rng.normal(0, 0.2, W))
    ctx = Context(times_s=times, covariates={"temperature_c": temp}, hints={})
    knee = CANDIDATES.get("temperature_bilinear")
    first = [(knee("EI:1", ctx), np.array([-0.055, 2.0, -0.0043]))]
    mirror = knee("EI:3", ctx)
    same = _same_course(first, mirror, np.array([-0.0082, 2.9, 0.0011]))
    assert same is not None and same[0] == first[0][0].label and abs(same[1]) >= SAME_COURSE
    step = CANDIDATES.get("step")("EI:2", ctx)
    assert _same_course(first, step, np.array([-0.04, times[400]])) is None
    hours = Context(times_s=times, covariates={"temperature_c": temp}, hints={"when": "hours",
                                                                              "hours_utc": [[7, 9.5], [17, 19.5]]})
    assert _same_course(first, CANDIDATES.get("added_mass")("mass", hours), np.array([0.05])) is None
    # a constant change (no course in time) is never taken for another's
    assert time_course(CANDIDATES.get("added_mass")("mass", ctx), np.array([0.05])) is None
