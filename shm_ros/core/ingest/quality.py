"""Per-channel checks of one window's samples: NaN/Inf, dead or stuck, clipped, spikes, noisy.

Plain numpy on one column; nothing is repaired, the caller flags samples and sets the channel
status from :class:`ChannelQuality`.
"""

from __future__ import annotations

import functools
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
    if q.hi - q.lo <= dead_ptp or _stuck(xf):
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


def _stuck(x: np.ndarray) -> bool:
    """One constant value for more than half of ``x``; a run is at most one sample longer than
    the number of zero steps, so counting them first settles most channels."""
    if x.size >= 2 and np.count_nonzero(x[1:] == x[:-1]) + 1 <= x.size / 2:
        return False
    return longest_constant_run(x) > x.size / 2


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
    if finite.all():
        y = x
    else:
        y = np.where(finite, x, np.median(x[finite]) if finite.any() else 0.0)
    padded = np.concatenate((y[:1], y[:1], y, y[-1:], y[-1:]))
    med5 = _median5(padded, n)
    a = np.abs(y - med5)
    d = np.diff(y)
    sigma = 1.4826 * float(np.median(np.abs(d - np.median(d))))
    half = max(3, int(rate / 2))
    # cs[j] = sum of d2[:j] with d2[i] = (y[i] - y[i-1])^2, d2[0] = 0, held at cs[0] and cs[n]
    # beyond both ends: cs at the clipped indices i - half, i + half + 1, i - 2, i + 3 are slices
    p = half + 1
    cs = np.empty(n + 2 * p + 1)
    cs[: p + 2] = 0.0
    np.cumsum(d * d, out=cs[p + 2: p + n + 1])
    cs[p + n + 1:] = cs[p + n]
    lo, hi = cs[p - half: p - half + n], cs[p + half + 1: p + half + 1 + n]
    ilo, ihi = cs[p - 2: p - 2 + n], cs[p + 3: p + 3 + n]
    local = np.sqrt(np.maximum(hi - lo - (ihi - ilo), 0.0) / _counts(n, half))
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


@functools.lru_cache(maxsize=4)
def _counts(n: int, half: int) -> np.ndarray:
    """Samples around each of ``n`` in the surrounding ``+-half`` without the 5 nearest (at least
    1): the divisor of the local RMS in :func:`spikes` (the same for every window of a length)."""
    i = np.arange(n)
    m = (np.minimum(i + half + 1, n) - np.maximum(i - half, 0)) - (np.minimum(i + 3, n) - np.maximum(i - 2, 0))
    out = np.maximum(m, 1).astype(np.float64)
    out.flags.writeable = False
    return out


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
