"""Per-channel checks of one window's samples: NaN/Inf, dead or stuck, clipped, spikes, noisy.

Plain numpy on one column; nothing is repaired, the caller flags samples and sets the channel
status from :class:`ChannelQuality`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class ChannelQuality:
    status: str  # ok | noisy | clipped | dead
    nan: np.ndarray  # NaN/Inf samples
    clipped: np.ndarray  # flat tops (or at/above the saturation level)
    spikes: np.ndarray  # isolated outliers (never a clipped sample)
    dead_reason: str | None = None  # "no finite sample" or "stuck" when status is dead
    lo: float = float("nan")  # finite minimum
    hi: float = float("nan")  # finite maximum
    median: float = float("nan")  # of the finite samples


def assess_channel(x: np.ndarray, rate: float, *, dead_ptp: float, clip_run: int,
                   saturation: float | None, spike_k: float, noisy_fraction: float) -> ChannelQuality:
    """Check one channel's samples ``x`` (n,) of a window sampled at ``rate`` Hz."""
    n = x.size
    finite = np.isfinite(x)
    none = np.zeros(n, bool)
    q = ChannelQuality("ok", ~finite, none, none)
    xf = x[finite]
    if xf.size == 0:
        q.status, q.dead_reason = "dead", "no finite sample"
        return q
    q.lo, q.hi = float(xf.min()), float(xf.max())
    if q.hi - q.lo <= dead_ptp or longest_constant_run(xf) > xf.size / 2:
        q.status, q.dead_reason = "dead", "stuck"
        return q
    q.median = float(np.median(xf))
    clip = clipped(x, q.lo, q.hi, q.median, clip_run)
    if saturation is not None:
        clip |= np.abs(np.nan_to_num(x, nan=0.0)) >= saturation
    q.clipped = clip
    q.spikes = spikes(x, finite, spike_k, rate) & ~clip
    if clip.any():
        q.status = "clipped"
    elif int(q.spikes.sum()) + int(q.nan.sum()) > noisy_fraction * n:
        q.status = "noisy"
    return q


def longest_constant_run(x: np.ndarray) -> int:
    if x.size < 2:
        return int(x.size)
    change = np.flatnonzero(np.diff(x) != 0)
    bounds = np.concatenate(([-1], change, [x.size - 1]))
    return int(np.diff(bounds).max())


def runs_at(mask: np.ndarray, min_run: int) -> np.ndarray:
    """Samples of ``mask`` that belong to runs of at least ``min_run`` consecutive True."""
    if not mask.any():
        return mask
    edges = np.diff(np.concatenate(([0], mask.view(np.int8), [0])))
    s = np.flatnonzero(edges == 1)
    e = np.flatnonzero(edges == -1)
    out = np.zeros_like(mask)
    for a, b in zip(s[(e - s) >= min_run], e[(e - s) >= min_run], strict=True):
        out[a:b] = True
    return out


def clipped(x: np.ndarray, lo: float, hi: float, med: float, min_run: int) -> np.ndarray:
    """Flat tops: runs of ``min_run``+ samples exactly at the channel's extreme, far from the median."""
    out = np.zeros(x.shape, bool)
    spread = max(hi - med, med - lo)
    for level in (hi, lo):
        if abs(level - med) < 0.5 * spread:
            continue
        out |= runs_at(x == level, min_run)
    return out


def spikes(x: np.ndarray, finite: np.ndarray, k: float, rate: float) -> np.ndarray:
    """Isolated samples farther than ``k`` sigmas from the median of the 5 samples around them.

    Sigma is the larger of the robust spread of the first differences over the window and their
    RMS over the surrounding second (without the 5 samples themselves): band-limited peaks and
    strong shaking are not spikes, a lone outlier in a quiet stretch is.
    """
    n = x.size
    if n < 7:
        return np.zeros(n, bool)
    y = np.where(finite, x, np.median(x[finite]) if finite.any() else 0.0)
    padded = np.concatenate((y[:1], y[:1], y, y[-1:], y[-1:]))
    med5 = _median5(padded, n)
    a = np.abs(y - med5)
    d = np.diff(y)
    sigma = 1.4826 * float(np.median(np.abs(d - np.median(d))))
    d2 = np.concatenate(([0.0], d * d))  # d2[i] = (y[i] - y[i-1])^2
    cs = np.concatenate(([0.0], np.cumsum(d2)))
    half = max(3, int(rate / 2))
    i = np.arange(n)
    lo, hi = np.clip(i - half, 0, n), np.clip(i + half + 1, 0, n)
    ilo, ihi = np.clip(i - 2, 0, n), np.clip(i + 3, 0, n)
    m = (hi - lo) - (ihi - ilo)
    local = np.sqrt(np.maximum(cs[hi] - cs[lo] - (cs[ihi] - cs[ilo]), 0.0) / np.maximum(m, 1))
    scale = np.maximum(sigma, local)
    if not np.any(scale > 0):
        return np.zeros(n, bool)
    big = a > k * scale
    if not big.any():
        return big
    # isolated: neither neighbour is big as well (oscillations are not spikes)
    nb = np.zeros(n, bool)
    nb[1:] |= big[:-1]
    nb[:-1] |= big[1:]
    return big & ~nb & finite


def _median5(y: np.ndarray, n: int) -> np.ndarray:
    """Element-wise median of ``y[j:j + n]`` over j = 0..4 (finite values): a seven-exchange
    selection network, in place (exact; several times faster than partitioning a sliding window)."""
    p = [y[j:j + n].copy() for j in range(5)]
    t = np.empty(n)
    for i, j in ((0, 1), (3, 4), (0, 3), (1, 4), (1, 2), (2, 3), (1, 2)):
        np.minimum(p[i], p[j], out=t)
        np.maximum(p[i], p[j], out=p[j])
        p[i], t = t, p[i]
    return p[2]
