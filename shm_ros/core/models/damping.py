"""Rayleigh damping ``C = a0 M + a1 K``: the coefficients that give two modal damping ratios.

The ratio of a mode at circular frequency w is ``zeta(w) = a0 / (2 w) + a1 w / 2``. Two ratios
``z1, z2`` at ``w1, w2`` fix a0, a1. When the two frequencies coincide (a symmetric structure's
repeated mode, or a reduced model at an extreme parameter) that system is singular: the damping then
falls back to mass-proportional with ``z1`` met exactly at ``w1`` (``a1 = 0``), instead of dividing
by zero. Scalars or arrays (broadcasting) alike: the likelihoods evaluate thousands of models at once.
"""

from __future__ import annotations

import numpy as np

__all__ = ["rayleigh_coefficients", "rayleigh_ratios", "COINCIDENT_RTOL"]

COINCIDENT_RTOL = 1e-12  # |w2 - w1| <= COINCIDENT_RTOL * max(w1, w2): the frequencies coincide


def rayleigh_coefficients(w1, w2, z1, z2):
    """a0, a1 of C = a0 M + a1 K giving ratios z1, z2 at circular frequencies w1, w2.

    Floats for scalar input, arrays (broadcast shape) otherwise. Coincident frequencies give the
    mass-proportional fallback ``a0 = 2 z1 w1, a1 = 0`` (see module doc).
    """
    w1, w2, z1, z2 = (np.asarray(v, dtype=float) for v in (w1, w2, z1, z2))
    same = np.abs(w2 - w1) <= COINCIDENT_RTOL * np.maximum(np.abs(w1), np.abs(w2))
    d = np.where(same, 1.0, w2**2 - w1**2)
    a0 = np.where(same, 2 * z1 * w1, 2 * w1 * w2 * (z1 * w2 - z2 * w1) / d)
    a1 = np.where(same, 0.0, 2 * (z2 * w2 - z1 * w1) / d)
    if a0.ndim == 0:
        return float(a0), float(a1)
    return a0, a1


def rayleigh_ratios(w, a0, a1):
    """Damping ratio a0 / (2 w) + a1 w / 2 of modes at circular frequencies ``w`` (broadcasting)."""
    w = np.asarray(w, dtype=float)
    return a0 / (2 * w) + a1 * w / 2
