"""explain on earthquake series in the time domain (docs/explain.md, "Time domain"): softening.

Truth outside the analysis model's class (:mod:`explain_td_cases`): six 60 s earthquakes (PGA 0.25-1.6
m/s^2) on the simulator's eight-story building with its default model-form error (damping ratios per
mode that no Rayleigh form gives, y-sway and torsion, non-classical damping), damper braces, nominal
story stiffnesses 10-20 % off; softening story springs ``f = k d / (1 + |d| / d_ref)`` (``drift_ref_m``
0.01 m: the strongest event's equivalent-linear first frequency 10-12 % below the small-amplitude one;
the stiffness changes within each event with the drift), or none (clean). The damping series is in
``test_explain_timedomain_damping.py``, the clean one in ``test_explain_timedomain_clean.py`` (their own
files, so that the series run on separate test workers).

Criteria (issue): right top name; parameter within 25 % of the truth's equivalent at the candidate's
resolution (:func:`explain_td_cases.truth_parameter_within`: the candidate's form fitted to the
simulator's equivalent-linear first frequency over one period around every segment); NRMS at least
halved on the calibration events and the held-out events improved (here also halved); clean: no
amplitude entry; evidence check within max(0.5, 3 SE) on accepted candidates. Seeds: CI runs seed 0 of
each series; SHM_FULL=1 runs 5 softening and 10 clean seeds. Each criterion is applied per seed, none
is a pooled statistic, so CI needs no relaxed threshold; the clean false-alarm rate is the shipped
threshold's calibration (``threshold_timedomain.json``: 99th percentile of 100 clean replicates).
Seed 0 (2026-11-29, a variance per event): NRMS 56.9 -> 13.5 %, held out 55.3 -> 12.3 %, within-event k
0.296 vs the truth's 0.283 s^2/m.
"""

from __future__ import annotations

import numpy as np
import pytest
from explain_td_cases import PGAS, STIFF, assert_found, run_series, top
from predict_synth import FULL

SEEDS = list(range(5)) if FULL else [0]


def test_series_spread_and_softening():
    s, _ = run_series(STIFF, 0)
    assert len(s.events) >= 6 and max(PGAS) / min(PGAS) >= 4
    pga = [e.pga_m_s2 for e in s.events]
    assert max(pga) / min(pga) >= 4
    assert np.min(s.f1 / s.f1_0) <= 0.92  # the strongest event's first frequency drops >= 8 %


@pytest.mark.parametrize("seed", SEEDS)
def test_softening_found(seed):
    assert_found(STIFF, seed)


@pytest.mark.parametrize("seed", SEEDS)
def test_softening_halves_nrms(seed):
    _, v = run_series(STIFF, seed)
    c = top(v)
    assert c.extra["resolution"] == "within_event"  # the stiffness changes within each event
    assert c.fit_after.nrms_pct <= 0.5 * v.fit_before.nrms_pct
    assert c.held_out_after.nrms_pct <= 0.5 * v.held_out_before.nrms_pct
