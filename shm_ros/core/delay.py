"""A fractional time shift of sampled signals (one helper for the simulator and the clock correction)."""

from __future__ import annotations

import numpy as np


def shift(x: np.ndarray, fs: float, offset_s: float) -> np.ndarray:
    """Channel(s) ``x`` (n, ...) moved ``offset_s`` earlier (a fractional delay by FFT phase; the
    record is treated as periodic, so a few samples at the ends are unreliable)."""
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    f = np.fft.rfftfreq(n, 1.0 / fs)
    phase = np.exp(2j * np.pi * f * offset_s).reshape((-1,) + (1,) * (x.ndim - 1))
    return np.fft.irfft(np.fft.rfft(x, axis=0) * phase, n=n, axis=0)
