"""Arias intensity of a record and its strong-motion part (used by the time-domain likelihood and the
prediction, which sits above it)."""

from __future__ import annotations

import numpy as np


def arias_fractions(a: np.ndarray) -> np.ndarray:
    """Cumulative Arias intensity of ``a`` (N,) normalised to 1 at the end (0 for a silent record)."""
    c = np.cumsum(np.asarray(a, dtype=float) ** 2)
    return c / c[-1] if c.size and c[-1] > 0 else np.zeros_like(c)


def strong_motion(a: np.ndarray, lo: float = 0.05, hi: float = 0.95) -> slice:
    """Samples between ``lo`` and ``hi`` of the Arias intensity of ``a`` (the strong-motion part)."""
    f = arias_fractions(np.asarray(a, dtype=float))
    return slice(int(np.searchsorted(f, lo)), int(np.searchsorted(f, hi)) + 1)
