"""Arias intensity and the strong-motion interval it bounds (significant duration)."""

from __future__ import annotations

import numpy as np

G = 9.80665  # m/s^2

__all__ = ["arias_intensity", "significant_interval"]


def arias_intensity(a: np.ndarray, fs: float) -> np.ndarray:
    """Cumulative Arias intensity ``pi / (2 g) * integral a^2 dt`` (m/s for a in m/s^2) of ``a`` (n,)
    or of the sum of squares of the columns of ``a`` (n, c); trapezoidal, starting at 0."""
    x = np.asarray(a, dtype=float)
    sq = x * x if x.ndim == 1 else np.sum(x * x, axis=1)
    out = np.zeros(sq.size)
    out[1:] = np.cumsum(0.5 * (sq[1:] + sq[:-1])) / fs
    return np.pi / (2 * G) * out


def significant_interval(a: np.ndarray, fs: float, low: float = 0.05, high: float = 0.95
                         ) -> tuple[float, float, float]:
    """``(t_low, t_high, total)``: the times (s from the first sample) at which the Arias intensity
    reaches the fractions ``low`` and ``high`` of its total (linear interpolation between samples)."""
    ia = arias_intensity(a, fs)
    total = float(ia[-1]) if ia.size else 0.0
    if total <= 0.0:
        raise ValueError("the record has no energy: no strong-motion interval")
    t = np.arange(ia.size) / fs
    frac = ia / total
    return float(np.interp(low, frac, t)), float(np.interp(high, frac, t)), total
