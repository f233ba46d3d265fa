"""Fit scores: frequency and damping RMSE on training and held-out windows, and the identification
scatter below which no model can fit."""

from __future__ import annotations

import math

import numpy as np

from .types import FitScores


def _rmse_pct(res: np.ndarray) -> float:
    v = res[np.isfinite(res)]
    return float(100.0 * np.sqrt(np.mean(np.expm1(v) ** 2))) if v.size else float("nan")


def scores(r: np.ndarray, delta: np.ndarray | None, train: np.ndarray, held: np.ndarray | None = None
           ) -> tuple[FitScores, FitScores]:
    """Frequency RMSE (%) on the training and held-out windows of residuals ``r`` (W, K) after the
    change ``delta`` (W, K), each mode's constant offset taken from the training windows; ``held``:
    the held-out windows scored (default: every window not in ``train``)."""
    e = r if delta is None else r - delta
    off = np.nanmean(e[train], axis=0)
    e = e - off
    return FitScores(_rmse_pct(e[train])), FitScores(_rmse_pct(e[~train if held is None else held]))


def judged_windows(times_s: np.ndarray, train: np.ndarray, span: tuple[float, float] | None) -> np.ndarray:
    """(W,) the held-out windows on which an effect starting within ``span`` (seconds since the first
    window; None: not at a moment) is judged: every held-out window but those between the last training
    window before the span and the first one at or after its end. The training windows cannot place
    the start among those (its likelihood is flat across them), so their prediction is a guess, for
    the effect as for the model without it; the windows after them, where the effect does differ from
    none, still judge it."""
    held = ~np.asarray(train, bool)
    if span is None or not held.any():
        return held
    t = np.asarray(times_s, float)
    idx = np.flatnonzero(train)
    before = idx[t[idx] < span[0]]
    after = idx[t[idx] >= span[1]]
    lo = int(before[-1]) if before.size else -1
    hi = int(after[0]) if after.size else len(t)
    out = held.copy()
    out[lo + 1:hi] = False
    return out


def scatter(x: np.ndarray | None, scale: float = 100.0) -> float | None:
    """The identification scatter of ``x`` (W, K) in time order, times ``scale``: per mode the robust
    spread of differences between consecutive windows over sqrt(2) (slow effects and single steps hardly
    enter), pooled as a root mean square over the modes. No model can fit below it: the misfit beyond
    it (``sqrt(RMSE^2 - scatter^2)``) is what a candidate can explain."""
    if x is None:
        return None
    out = []
    for k in range(x.shape[1]):
        v = x[np.isfinite(x[:, k]), k]
        if v.size > 3:
            d = np.diff(v)
            out.append((1.4826 * float(np.median(np.abs(d - np.median(d)))) / math.sqrt(2)) ** 2)
    return float(scale * math.sqrt(np.mean(out))) if out else None


def damping_scores(z: np.ndarray | None, ln_factor: np.ndarray | None, train: np.ndarray,
                   held: np.ndarray | None = None) -> tuple[float | None, float | None]:
    """Damping-ratio RMSE in percentage points on the training and held-out windows: the observed
    ratios ``z`` (W, K) against each mode's typical ratio (geometric mean over the training windows)
    times the candidate's factor ``exp(ln_factor)`` (W, 1 or K; None: no change); ``held`` as in
    :func:`scores`."""
    if z is None:
        return None, None
    lz = np.log(np.where(z > 0, z, np.nan))
    lf = 0.0 if ln_factor is None else ln_factor
    off = np.nanmean((lz - lf)[train], axis=0)
    e = z - np.exp(off + lf)

    def rms(a: np.ndarray) -> float | None:
        v = a[np.isfinite(a)]
        return float(100 * np.sqrt(np.mean(v ** 2))) if v.size else None

    return rms(e[train]), rms(e[~train if held is None else held])

