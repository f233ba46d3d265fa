"""Is what remains noise? The per-mode whiteness of the misfit before and after the accepted effects
(:mod:`shm_ros.core.explain.whiteness`), on series whose answer is known."""

from __future__ import annotations

import numpy as np

from shm_ros.core.explain.whiteness import STRUCTURED_P, autocorrelation, ljung_box, residual_whiteness


def _ar1(rng: np.random.Generator, n: int, rho: float) -> np.ndarray:
    x = np.zeros(n)
    e = rng.standard_normal(n)
    for i in range(1, n):
        x[i] = rho * x[i - 1] + e[i]
    return x


def test_white_noise_is_white_and_a_slow_course_is_not():
    rng = np.random.default_rng(11)
    white = [ljung_box(rng.standard_normal(576)) for _ in range(50)]
    # at the 1e-3 level, 50 white series give no false call with probability 0.95; none here
    assert min(white) > STRUCTURED_P, min(white)
    slow = _ar1(rng, 576, 0.8)
    assert ljung_box(slow) < 1e-12
    assert abs(autocorrelation(slow, 1)[0] - 0.8) < 0.1


def test_missing_windows_do_not_make_structure():
    rng = np.random.default_rng(12)
    r = rng.standard_normal(576)
    r[rng.random(576) < 0.2] = np.nan
    assert ljung_box(r) > STRUCTURED_P
    assert abs(autocorrelation(r, 1)[0]) < 0.15


def test_the_note_names_the_modes_whose_structure_is_left():
    rng = np.random.default_rng(13)
    n = 576
    course = np.sin(2 * np.pi * np.arange(n) / 144.0)  # a daily course the nominal model misses
    before = np.column_stack([course + 0.2 * rng.standard_normal(n) for _ in range(3)])
    # after the accepted effect: mode 1 white, mode 2 keeps half of the course, mode 3 a tenth of it
    # (significant on 576 windows, too small to matter: not listed)
    after = 0.2 * rng.standard_normal((n, 3))
    after[:, 1] += 0.5 * course
    after[:, 2] += 0.1 * course
    w = residual_whiteness(before, after, [1, 2, 3])
    assert w.p_after[2] < STRUCTURED_P and w.lag1_after[2] < 0.3
    assert w.still_structured == [2]
    assert w.lag1_before[0] > 0.8 and abs(w.lag1_after[0]) < 0.15 and w.lag1_after[1] > 0.5
    note = w.note()
    assert note is not None and "mode 2 " in note and "mode 1" not in note
    d = w.to_dict()
    assert d["still_structured"] == [2] and len(d["ljung_box_p_after"]) == 3
    assert residual_whiteness(before, 0.2 * rng.standard_normal((n, 3)), [1, 2, 3]).note() is None


def test_the_terminal_verdict_says_whether_the_misfit_left_is_noise():
    from shm_ros.commands.explain import format_verdict

    fit = {"before": {"frequency_rmse_pct": 3.3}, "after": {"frequency_rmse_pct": 0.6},
           "held_out": {"before": {"frequency_rmse_pct": 2.2}, "after": {"frequency_rmse_pct": 0.5}}}
    v = {"mismatch": {"summary": "s"}, "fit": fit,
         "missing_physics": [{"name": "temperature_dependent_stiffness", "form": "bilinear",
                              "log_evidence_gain": 488.8}]}
    w = {"mode_numbers": [1, 2, 9], "lag1_after": [0.05, 0.37, 0.80], "still_structured": [2, 9]}
    fit["residual_whiteness"] = w
    assert "misfit left: a course in time on modes 2, 9 (lag-1 autocorrelation 0.37, 0.80)" in format_verdict(v)
    w.update(lag1_after=[0.05, 0.12, 0.08], still_structured=[])
    assert "misfit left: noise on every mode (lag-1 autocorrelation at most 0.12)" in format_verdict(v)
    v["missing_physics"] = []  # nothing named: nothing to say about what it left
    assert "misfit left" not in format_verdict(v)
