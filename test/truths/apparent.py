"""Apparent modal properties of a recorded event: what a quick look at the records shows.

``transfer_peak``: the peak of the smoothed ground-to-floor transfer function (centroid: finer than
one bin); ``arx_mode``: the lowest mode of a least-squares ARX model; ``strong_part``: the
strong-motion phase of a record. Used by the tests and the effect-size audit, not by the generator.
"""

from __future__ import annotations

import numpy as np


def transfer_peak(ground: np.ndarray, top: np.ndarray, rate: float, band: tuple[float, float] = (1.0, 8.0),
                  smooth_hz: float = 0.25) -> float:
    """Frequency (Hz) of the peak of |top / ground|^2 in ``band``, spectra smoothed over ``smooth_hz``."""
    n = ground.size
    freqs = np.fft.rfftfreq(n, 1 / rate)
    width = max(1, int(smooth_hz / freqs[1]))
    k = np.ones(width) / width
    tf = (np.convolve(np.abs(np.fft.rfft(top * np.hanning(n))) ** 2, k, "same")
          / np.convolve(np.abs(np.fft.rfft(ground * np.hanning(n))) ** 2, k, "same"))
    sel = (freqs > band[0]) & (freqs < band[1])
    peak = float(freqs[sel][np.argmax(tf[sel])])
    near = np.abs(freqs - peak) < 0.3
    return float(np.sum(freqs[near] * tf[near]) / np.sum(tf[near]))


def arx_mode(ground: np.ndarray, top: np.ndarray, rate: float, order: int) -> tuple[float, float]:
    """(frequency Hz, damping ratio) of the lowest mode of an ARX model of ``order`` fitted by least
    squares: y[k] = sum a_i y[k-i] + sum b_i u[k-i] (i = 0..order for u). Measurement noise biases
    both a little, the same way in the clean and the effect campaign."""
    n = ground.size
    rows = np.column_stack([top[order - i - 1: n - i - 1] for i in range(order)]
                           + [ground[order - i: n - i] for i in range(order + 1)])
    coef, *_ = np.linalg.lstsq(rows, top[order:], rcond=None)
    poles = np.roots(np.concatenate([[1.0], -coef[:order]]))
    s_poles = np.log(poles.astype(complex)) * rate
    s_poles = s_poles[s_poles.imag > 2 * np.pi * 0.5]
    i = int(np.argmin(np.abs(s_poles)))
    wn = float(np.abs(s_poles[i]))
    return wn / (2 * np.pi), float(-s_poles[i].real / wn)


def strong_part(ground: np.ndarray, rate: float, level: float = 0.3) -> slice:
    """From the first to the last second where the ground's 1 s RMS exceeds ``level`` of its maximum
    (the strong-motion phase, where amplitude-dependent physics acts)."""
    n = max(1, int(rate))
    rms = np.sqrt(np.convolve(ground**2, np.ones(n) / n, "same"))
    on = np.flatnonzero(rms > level * rms.max())
    return slice(int(on[0]), int(on[-1]) + 1)
