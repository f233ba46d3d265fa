"""explain on earthquake series in the time domain: amplitude-dependent damping (docs/explain.md).

The series of :mod:`explain_td_cases` with story dashpots ``f = c v (1 + |v| / v_ref)`` (``velocity_ref_m_s``
0.02 m/s) in the simulator's truth, outside the analysis model's class (its damping is Rayleigh plus the
damper braces; the truth's grows the higher modes' damping more than the first's).

Criteria (issue): right top name; damping parameter within 25 % of the truth's equivalent at the
candidate's resolution; held-out events improved; evidence check; and damping RMSE at least halved
(first-mode damping per segment against the simulator's equivalent-linear one, each model's constant
offset from the truth taken out as for the frequencies of modal tables and reported beside it:
:func:`explain_td_cases.damping_rmse`). CI runs seed 0, SHM_FULL=1 seeds 0-4, every criterion per seed.

The offset is the calibrated planar model's model-form bias: its first-mode damping sits 0.1-0.4
points above the truth's with or without the effect, since it takes up the torsional part that
eccentric masses and off-centre sensors put into the records (docs/explain.md, "The damping RMSE and its offset").
With the offset in, the RMSE was halved on seeds 1-3 only (seed 0 0.50 -> 0.37, seed 4 0.24 -> 0.19
points); with it out, 0.28 -> 0.03 and 0.21 -> 0.07 on those two.
"""

from __future__ import annotations

import pytest
from explain_td_cases import DAMP, assert_found, damping_rmse, run_series, top
from predict_synth import FULL

SEEDS = list(range(5)) if FULL else [0]


@pytest.mark.parametrize("seed", SEEDS)
def test_damping_found(seed):
    assert_found(DAMP, seed)


@pytest.mark.parametrize("seed", SEEDS)
def test_damping_rmse_halved(seed):
    s, v = run_series(DAMP, seed)
    m = damping_rmse(s, v, top(v))
    print(f"seed {seed}: first-mode damping RMSE {m.before:.3f} -> {m.after:.3f} points (offsets "
          f"{m.offset_before:+.3f}, {m.offset_after:+.3f}; with them in {m.raw_before:.3f} -> {m.raw_after:.3f})")
    assert m.after <= 0.5 * m.before
