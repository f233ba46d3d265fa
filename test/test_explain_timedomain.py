"""explain on earthquake series in the time domain (docs/explain.md, "Time domain").

Truth outside the analysis model's class (:mod:`explain_td_cases`): six 60 s earthquakes (PGA 0.25-1.6
m/s^2) on the simulator's eight-story building with its default model-form error, nominal story
stiffnesses 10-20 % off; softening story springs (``drift_ref_m`` 0.01 m: the strongest event's
equivalent-linear first frequency 10-12 % below the small-amplitude one) or amplitude-dependent story
dashpots (``velocity_ref_m_s`` 0.02 m/s), or neither (clean). The truth's equivalent of a candidate's
parameter is defined in :mod:`explain_td_cases` (the candidate's form fitted to the simulator's
per-event equivalent-linear first-mode frequency / damping over the strong motion).

Criteria (issue): right top name; parameter within 25 % of the truth's equivalent; NRMS at least halved
on the calibration events and held-out events improved; clean: no amplitude entry; evidence check within
max(0.5, 3 SE) on accepted candidates. Seeds: CI runs seed 0 of the softening and the clean series
(each criterion is applied per seed, as under SHM_FULL, where 5 seeds per effect and 10 clean seeds
must all pass; no pooled
statistic is thresholded, so no CI relaxation is needed). The damping series runs under SHM_FULL only
(about 40 s a seed). Criteria the per-event equivalent-linear method does not meet are kept and marked
``xfail(strict=True)`` with the measured numbers (seed 0): NRMS 73.4 % -> 46.4 % on the softening
series (a factor 1.6; with a free stiffness factor per event the best is 38 %: the stiffness changes
within each event, which no per-event linear model follows); damping parameter 0.168 vs the truth's
0.362 s^2/m. With the shipped threshold (60.3 nats from 6 clean replicates, two of which gave 37.7
and 60.3 on a candidate) the damping series of seed 0 (gain 27.8) is not accepted, so
``test_damping_found`` is expected to fail under SHM_FULL.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from explain_td_cases import PGAS, event_series, truth_parameter
from predict_synth import FULL

from shm_ros.core.explain.timedomain import TimeDomainConfig, explain_events
from shm_ros.core.structure import structure_from_dict

STIFF, DAMP = "amplitude_dependent_stiffness", "amplitude_dependent_damping"
SEEDS = list(range(5)) if FULL else [0]
CLEAN_SEEDS = list(range(10)) if FULL else [0]


@functools.cache
def _run(name: str | None, seed: int):
    s = event_series(seed, name)
    v = explain_events(s.events, structure_from_dict(s.structure), TimeDomainConfig(seed=seed))
    return s, v


def _top(v):
    assert v.missing_physics, f"nothing accepted: {[(c.label, c.reasons) for c in v.tried]}"
    return v.missing_physics[0]


def _truth_k(s, v, c) -> float:
    amp = np.array(v.figures["events"]["rms_accel_m_s2"])
    return truth_parameter(s, amp, c.extra["inherent_damping_ratio_1"])


def _check_agrees(v) -> None:
    """Laplace and importance sampling agree on every accepted candidate (the check runs on accepted
    ones, as for tables). On rejected ones whose effect sits at its null bound they differed by 0.8-3
    nats (seeds 0 and 2000), so they are not asserted there."""
    for c in v.missing_physics:
        tol = max(0.5, 3 * float(c.extra["check_err"]))
        assert abs(c.log_evidence_gain - c.log_evidence_gain_check) <= tol, (c.label, c.log_evidence_gain,
                                                                                c.log_evidence_gain_check, tol)


def test_series_spread_and_softening():
    s, _ = _run(STIFF, 0)
    assert len(s.events) >= 6 and max(PGAS) / min(PGAS) >= 4
    pga = [e.pga_m_s2 for e in s.events]
    assert max(pga) / min(pga) >= 4
    assert np.min(s.f1 / s.f1_0) <= 0.92  # the strongest event's first frequency drops >= 8 %


@pytest.mark.parametrize("seed", SEEDS)
def test_softening_found(seed):
    s, v = _run(STIFF, seed)
    c = _top(v)
    k, k_true = c.parameters["softening_per_accel"], _truth_k(s, v, c)
    print(f"seed {seed}: k {k:.3f} truth {k_true:.3f} gain {c.log_evidence_gain:.1f} (check "
          f"{c.log_evidence_gain_check:.1f}) NRMS {v.fit_before.nrms_pct:.1f} -> {c.fit_after.nrms_pct:.1f} %, "
          f"held out {v.held_out_before.nrms_pct:.1f} -> {c.held_out_after.nrms_pct:.1f} %")
    assert c.name == STIFF
    assert abs(k / k_true - 1) <= 0.25
    assert c.held_out_after.nrms_pct < v.held_out_before.nrms_pct
    _check_agrees(v)


@pytest.mark.xfail(strict=True, reason="per-event equivalent-linear stiffness: NRMS 73.4 -> 46.4 % (seed 0), "
                                       "not halved; see the module doc")
@pytest.mark.parametrize("seed", SEEDS)
def test_softening_halves_nrms(seed):
    _, v = _run(STIFF, seed)
    assert _top(v).fit_after.nrms_pct <= 0.5 * v.fit_before.nrms_pct


@pytest.mark.parametrize("seed", CLEAN_SEEDS)
def test_clean_has_no_amplitude_entry(seed):
    _, v = _run(None, seed)
    print(f"seed {seed}: gains {[(c.label, round(c.log_evidence_gain, 1)) for c in v.tried]}")
    assert not [c for c in v.missing_physics if c.name in (STIFF, DAMP)]


@pytest.mark.skipif(not FULL, reason="SHM_FULL=1 (about 40 s a seed)")
@pytest.mark.parametrize("seed", SEEDS)
def test_damping_found(seed):
    s, v = _run(DAMP, seed)
    c = _top(v)
    print(f"seed {seed}: k {c.parameters['damping_per_accel']:.3f} truth {_truth_k(s, v, c):.3f} "
          f"NRMS {v.fit_before.nrms_pct:.1f} -> {c.fit_after.nrms_pct:.1f} %")
    assert c.name == DAMP
    assert c.held_out_after.nrms_pct < v.held_out_before.nrms_pct
    _check_agrees(v)


@pytest.mark.skipif(not FULL, reason="SHM_FULL=1")
@pytest.mark.xfail(strict=True, reason="damping factor on the inherent (Rayleigh) damping: 0.168 vs 0.362 (seed 0)")
@pytest.mark.parametrize("seed", SEEDS)
def test_damping_parameter(seed):
    s, v = _run(DAMP, seed)
    c = _top(v)
    assert abs(c.parameters["damping_per_accel"] / _truth_k(s, v, c) - 1) <= 0.25


def test_verdict_json_backward_compatible():
    _, v = _run(None, 0)
    d = v.to_dict()
    assert set(d) >= {"mismatch", "missing_physics", "fit", "candidates", "threshold", "notes"}
    assert "nrms_pct" in d["fit"]["before"] and "frequency_rmse_pct" not in d["fit"]["before"]
