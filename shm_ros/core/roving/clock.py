"""Clock offset between a roving sensor and the fixed references, from their cross-spectra.

Ambient response with (nearly) real modes has a real cross-spectrum between any two points: its
phase is 0 or pi at every frequency. A clock offset ``tau`` of one channel adds the phase
``-2 pi f tau``. Doubling the phase removes the 0 / pi ambiguity, so the offset maximises the
coherence-weighted sum ``|sum_f w(f) exp(2 i (phase(f) + 2 pi f tau))|`` over the band where the
channels are coherent (a cross-correlation in the frequency domain, insensitive to the shapes'
signs). The estimate is unique for ``|tau| < 1 / (4 f_max)``; it is searched on a grid over
``max_offset_s`` and refined by a parabola through the peak.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.signal as sig

from shm_ros.errors import InputError

__all__ = ["ClockOffset", "estimate_clock_offset"]


@dataclass
class ClockOffset:
    """``offset_s``: how late the roving channel's stamps are (its sample stamped t happened at
    t - offset); ``strength``: the normalised peak (1 = every frequency agrees)."""

    offset_s: float
    strength: float
    band_hz: tuple[float, float]


def estimate_clock_offset(roving: np.ndarray, references: np.ndarray, fs: float, max_offset_s: float = 0.05,
                          coherence_min: float = 0.5, segment_s: float | None = None) -> ClockOffset:
    """Offset of the ``roving`` channel (n,) against the ``references`` (n, r) recorded over the
    same stretch (see module doc); the references' evidence is summed."""
    x = np.asarray(roving, dtype=float).ravel()
    refs = np.asarray(references, dtype=float).reshape(x.size, -1)
    nper = min(x.size, int(segment_s * fs) if segment_s else 2 ** int(np.log2(max(256, x.size // 16))))
    if nper < 64:
        raise InputError(f"clock offset: {x.size} samples are too few")
    acc = None
    f = np.zeros(0)
    for k in range(refs.shape[1]):
        f, pxy = sig.csd(refs[:, k], x, fs=fs, nperseg=nper)
        _, coh = sig.coherence(refs[:, k], x, fs=fs, nperseg=nper)
        w = np.where(coh >= coherence_min, coh, 0.0)  # unit weight per coherent line
        z = w * np.exp(2j * np.angle(pxy))
        acc = z if acc is None else acc + z
    assert acc is not None
    used = np.flatnonzero(np.abs(acc) > 0)
    if used.size < 3:
        raise InputError(f"clock offset: fewer than 3 frequencies with coherence >= {coherence_min} between "
                         "the roving sensor and the references")
    taus = np.linspace(-max_offset_s, max_offset_s, 2001)
    # csd(ref, x) = E[conj(R) X]: X delayed by tau (x(t) = s(t - tau)) adds -2 pi f tau
    score = np.abs(np.exp(4j * np.pi * np.outer(taus, f[used])) @ acc[used])
    k = int(np.argmax(score))
    tau = taus[k]
    if 0 < k < taus.size - 1:
        a, b, c = score[k - 1], score[k], score[k + 1]
        den = a - 2 * b + c
        if den < 0:
            tau += 0.5 * (a - c) / den * (taus[1] - taus[0])
    return ClockOffset(float(tau), float(score[k] / np.sum(np.abs(acc[used]))),
                       (float(f[used].min()), float(f[used].max())))


