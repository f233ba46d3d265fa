"""The common sample grid: rate estimate, grid times, snapping stamps to grid rows, following a
drifting clock.

All channels share one grid ``anchor_t + (k - anchor_k) * period`` (integer nanoseconds; float64
alone cannot hold epoch nanoseconds). A stamp *snaps* to the nearest grid point when it lies
strictly within ``tolerance`` of it; nothing is interpolated. A stamp that cannot be snapped (too
far from every grid point, or beaten to its grid point by a closer stamp of the same channel)
leaves its grid point empty: a gap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MAX_RATE_HZ = 100_000.0  # the fastest sample rate ingest accepts (a window's grid is window_s x rate rows)
MIN_RATE_HZ = 0.1  # the slowest: a period of 10 s (slower is no vibration record)


def estimate_rate(stamps: np.ndarray, nominal: bool = True) -> float | None:
    """Sample rate (Hz) of jittered stamps: the median interval over 16 samples, refined by
    least-squares fits over growing spans; within 0.5 % of a whole number of Hz it is rounded
    (``nominal``). None when fewer than 17 distinct stamps, or outside ``MIN_RATE_HZ`` .. ``MAX_RATE_HZ``."""
    ts = np.sort(np.asarray(stamps, np.int64))
    ts = ts[np.concatenate(([True], np.diff(ts) > 0))]
    if ts.size < 17:
        return None
    lag = 16
    slope = float(np.median((ts[lag:] - ts[:-lag]) / lag))
    if not slope > 0:
        return None
    rel = (ts - ts[0]).astype(np.float64)
    for m in (64, 256, ts.size):
        m = min(m, ts.size)
        k = np.rint(rel[:m] / slope)
        if k[-1] > 0:
            slope = float(np.polyfit(k, rel[:m], 1)[0])
    rate = 1e9 / slope
    if not MIN_RATE_HZ <= rate <= MAX_RATE_HZ:  # stamps this dense or sparse are no accelerometer's
        return None
    if nominal and abs(rate - round(rate)) < 5e-3 * rate:
        rate = float(round(rate))
    return rate


def grid_time(origin: int, k: int, period_ns: float) -> int:
    """Time of grid point ``k`` counted from ``origin``."""
    return origin + int(round(k * period_ns))


def grid_edge(origin: int, k: int, period_ns: float) -> int:
    """First integer stamp that snaps to grid point ``k`` or later (half a period before it)."""
    return origin + int(math.ceil(k * period_ns - period_ns / 2))


@dataclass
class Grid:
    """Grid point ``k`` is at ``anchor_t + (k - anchor_k) * period``."""

    anchor_t: int
    anchor_k: int
    period: float  # ns

    def time(self, k: int) -> int:
        return grid_time(self.anchor_t, k - self.anchor_k, self.period)

    def edge(self, k: int) -> int:
        """First stamp that snaps to point ``k`` or later: stamps in ``[edge(k0), edge(k1))``
        belong to rows ``[k0, k1)``."""
        return grid_edge(self.anchor_t, k - self.anchor_k, self.period)

    def slot(self, t: int) -> int:
        """The grid point nearest to stamp ``t``."""
        return self.anchor_k + int(np.rint((t - self.anchor_t) / self.period))


@dataclass
class Snap:
    """Where the samples of one channel go in grid rows ``[k0, k0 + n)``."""

    rows: np.ndarray  # row of each placed sample (relative to k0)
    placed: np.ndarray  # index (into the inputs) of each placed sample
    dup_rows: np.ndarray  # rows that had a second sample with the same stamp as the placed one
    n_dup_differ: int  # of those copies, how many had a different value
    dup_t0: int | None  # first duplicated stamp
    n_collide: int  # samples that lost their grid point to a closer stamp
    collide_t0: int | None
    n_far: int  # samples farther than the tolerance from every grid point
    far_t0: int | None
    # every input placed, in order, on consecutive rows: those rows (``rows`` as a slice)
    run: slice | None = None


def snap(t: np.ndarray, v: np.ndarray, seq: np.ndarray, grid: Grid, k0: int, tolerance_ns: float) -> Snap:
    """Snap stamps ``t`` (values ``v``, arrival order ``seq``) to the grid. Of several stamps on one
    grid point the closest wins, then the earliest to arrive."""
    P = grid.period
    rel = (t - grid.anchor_t).astype(np.float64)
    k = np.rint(rel / P).astype(np.int64)
    resid = np.abs(rel - k * P)
    k += grid.anchor_k
    snappable = resid < tolerance_ns
    n_far = int((~snappable).sum())
    if not n_far and bool(np.all(k[1:] > k[:-1])):  # one stamp per grid point, in order (no sort)
        rows = k - k0
        run = slice(int(rows[0]), int(rows[-1]) + 1) if rows.size and rows[-1] - rows[0] == rows.size - 1 else None
        return Snap(rows=rows, placed=np.arange(k.size), dup_rows=np.empty(0, np.int64), n_dup_differ=0,
                    dup_t0=None, n_collide=0, collide_t0=None, n_far=0, far_t0=None, run=run)
    order = np.lexsort((seq, resid, k))
    order = order[snappable[order]]
    ks = k[order]
    first = np.ones(ks.size, bool)
    first[1:] = ks[1:] != ks[:-1]
    win = order[first]
    lose = order[~first]
    dup_rows = np.empty(0, np.int64)
    n_differ, dup_t0, n_collide, collide_t0 = 0, None, 0, None
    if lose.size:
        # each loser against the winner of its grid point: the same stamp is a duplicate
        per_point = np.diff(np.append(np.flatnonzero(first), ks.size))
        win_t = np.repeat(t[win], per_point)[~first]
        win_v = np.repeat(v[win], per_point)[~first]
        dup = t[lose] == win_t
        if dup.any():
            dup_rows = k[lose][dup] - k0
            n_differ = int((v[lose][dup] != win_v[dup]).sum())
            dup_t0 = int(t[lose][dup][0])
        n_collide = int((~dup).sum())
        if n_collide:
            collide_t0 = int(t[lose][~dup][0])
    return Snap(rows=k[win] - k0, placed=win, dup_rows=dup_rows, n_dup_differ=n_differ, dup_t0=dup_t0,
                n_collide=n_collide, collide_t0=collide_t0, n_far=n_far,
                far_t0=int(t[~snappable][0]) if n_far else None)


@dataclass
class ClockFit:
    """The stamps' clock over some rows: grid point k0 at ``t0 + offset``, ``period`` ns."""

    offset: float  # ns
    period: float  # ns
    period_se: float  # standard error of ``period``


def fit_clock(ts: np.ndarray, t0: int, period: float, n_rows: int) -> ClockFit | None:
    """Fit ``t = t0 + a + b (k - k0)`` to the sorted stamps ``ts`` of ``n_rows`` grid rows from grid
    point k0 at ``t0`` (outliers beyond half a period left out, the fit widened over 64, 256, ...
    rows as the period gets known, as in :func:`estimate_rate`); None when too few stamps."""
    if ts.size < 64 or n_rows < 64:
        return None
    rel = (ts - t0).astype(np.float64)
    a, b = 0.0, period
    stages, rows = [], 64
    while rows < n_rows:
        stages.append(rows)
        rows *= 4
    stages.append(n_rows)
    se_b = np.inf
    for rows in stages:
        m = int(np.searchsorted(rel, (rows - 0.5) * period))
        r, kk = rel[:m], np.rint((rel[:m] - a) / b)
        res = r - (a + b * kk)
        good = np.abs(res) < 0.5 * b
        if good.sum() < 32 or np.ptp(kk[good]) < 32:
            return None
        kg, rg = kk[good], r[good]
        kc, rc = kg - kg.mean(), rg - rg.mean()
        spread = float(kc @ kc)
        if spread <= 0:
            return None
        b = float(kc @ rc) / spread  # least-squares line, closed form
        a = float(rg.mean() - b * kg.mean())
        se_b = float(np.std(rc - b * kc)) / math.sqrt(spread)
    return ClockFit(a, b, se_b)


def follow_clock(fit: ClockFit, t0: int, period: float, n_rows: int, rate_tolerance: float
                 ) -> tuple[int, float] | None:
    """The new ``(anchor_t, period)`` for grid point k0 when the stamps' clock departs from the grid,
    None when the grid stays. The period follows a significant trend (4 standard errors) of more
    than a tenth of a period over the rows; the grid point stays put unless the stamps sit a quarter
    period or more away from it (constant offsets between IMUs are what the half-period tolerance
    is for); a clock off by more than ``rate_tolerance`` is a rate mismatch, not drift."""
    b, a = fit.period, fit.offset
    slope_drift = abs(b - period) * n_rows if abs(b - period) > 4 * fit.period_se else 0.0
    shift = int(round(a)) if abs(a) >= 0.25 * period else 0
    if (slope_drift > 0.1 * period or shift) and abs(b - period) < rate_tolerance * period:
        return t0 + shift, (float(b) if slope_drift > 0.1 * period else period)
    return None
