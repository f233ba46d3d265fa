"""The girder-roving scenario end to end at reduced size (3 seeds, 10 points, 60 s dwells, 50 Hz):
tf tracks -> setups -> clock offset -> per-setup identification -> setups merged, against the truth
without the robot (model-form error on). Full size: ``SHM_FULL=1`` (10 seeds drawn from the git tree
of shm_ros/core/roving, 12 points, 120 s dwells, 100 Hz; docs/roving.md has the latest result).

At full size the acceptance's own limits apply (frequencies within 0.5 %, MAC >= 0.98). At reduced
size (60-s setups at 50 Hz) a correct pipeline scatters more, so the limits are set for a >= 99 % pass
of three seeds (per-seed failure <= 0.33 %): over development seeds 100-199 at reduced size (at
`f1901c7`), a Student-t fitted per mode to the frequency errors puts the chance of any of modes 1-3
beyond 1.4 % at 0.22 % a seed, and one fitted per mode to log10(1 - MAC) puts a MAC below 0.85 at
0.07 %: 0.29 % together, a 99.1 % pass of three seeds (largest error seen 1.13 %, smallest MAC
0.875; docs/roving.md).
"""

from __future__ import annotations

import os

import numpy as np
import pytest
import roving_acceptance as ra
import synthetic_oma as so

FULL = os.environ.get("SHM_FULL") == "1"
SEEDS = ra.acceptance_seeds() if FULL else range(3)  # full size: drawn from the pipeline's tree
SIZE = dict(dwell_s=120.0, n_points=12, fs=100.0) if FULL else dict(dwell_s=60.0, n_points=10, fs=50.0)
FREQ_PCT, MAC_MIN = (0.5, 0.98) if FULL else (1.4, 0.85)  # see the module doc


@pytest.mark.parametrize("seed", SEEDS)
def test_girder_roving_acceptance(seed):
    with so.single_blas_thread():
        out = ra.run(seed, **SIZE)
    rec, res = out.rec, out.res
    # every stop is a setup, at the right point, keeping >= 95 % of its dwell's samples
    dwells = [(t0, t1, p) for kind, t0, t1, p in rec.phases if kind == "dwell"]
    assert [s.points["r1"] for s in res.cut.setups] == [p for _, _, p in dwells]
    t = rec.times_ns * 1e-9
    for s, (t0, t1, _) in zip(res.cut.setups, dwells, strict=True):
        assert s.samples >= 0.95 * np.sum((t >= t0) & (t <= t1))
    # samples left out lie within one tf period of the drive phases, as the filtered positions show
    # them (the acceptance's wording: positions after the documented noise-and-jump filter, to which
    # the tolerance applies; docs/roving.md "Setups' edges") ...
    period = int(round(0.1 * SIZE["fs"]))  # one tf period (10 Hz) in samples
    left = np.flatnonzero(np.all(res.cut.point_index == -1, axis=1))
    moving = np.convolve(res.cut.moving.astype(float), np.ones(2 * period + 1), mode="same") > 0.5
    assert moving[left].all() and res.cut.missing_samples == 0 and not res.cut.errors()
    # ... and those drive phases are the truth's to within one tf period
    near = np.zeros(t.size, bool)
    for kind, t0, t1, _ in rec.phases:
        if kind == "drive":
            near |= (t >= t0 - 0.1) & (t <= t1 + 0.1)
    assert near[res.cut.moving].all(), t[res.cut.moving & ~near][:5]
    # the clock offset, reported within 2 ms
    assert abs(res.clock_offset_s - rec.clock_offset_s) < 0.002, res.clock_offset_s
    # vertical modes 1-3 within 0.5 % of the truth without the robot (reduced size: module doc)
    assert np.all(np.abs(out.freq_err_pct) < FREQ_PCT), out.freq_err_pct
    # modes 1-3 over every visited point and reference with MAC >= 0.98 (the roving components from
    # the references' transmissibility on the merged reference shapes: docs/roving.md; reduced size:
    # module doc)
    assert all(c == 1.0 for c in out.coverage) and all(m >= MAC_MIN for m in out.macs), (out.coverage, out.macs)
