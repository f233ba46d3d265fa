"""Roving components from the references' transmissibility (shm_ros/core/roving/transmissibility.py):
two modes 5 % apart seen by two references, whose roving components the setup's own picking would mix."""

from __future__ import annotations

import numpy as np
import scipy.signal as sig

from shm_ros.core.roving.transmissibility import roving_components

FS = 50.0


def _resonance(rng: np.random.Generator, n: int, f: float, zeta: float) -> np.ndarray:
    w = 2 * np.pi * f / FS
    r = np.exp(-zeta * w)
    return sig.lfilter([1.0], [1.0, -2 * r * np.cos(w * np.sqrt(1 - zeta ** 2)), r * r], rng.standard_normal(n))


def test_close_modes_are_separated_through_the_references():
    rng = np.random.default_rng(3)
    n = int(120 * FS)
    f, z = [16.5, 17.4], [0.012, 0.009]
    q = np.column_stack([_resonance(rng, n, fi, zi) for fi, zi in zip(f, z, strict=True)])
    q[:, 1] *= 2.0  # the neighbour stronger than the mode of interest
    refs = np.array([[-0.85, 1.0], [1.0, 0.4]])  # rows: references; columns: modes
    rov = np.array([[0.7, -0.9]])  # the roving point's components
    phi = np.vstack([refs, rov])
    y = q @ phi.T + 1e-3 * np.std(q) * rng.standard_normal((n, 3))
    for j in range(2):
        g = refs[:, j] * 3.0  # any scale: the result is on the references' scale
        val, err = roving_components(y, FS, 2, f[j], z[j], g)
        assert abs(val[0] - 3.0 * rov[0, j]) < 0.03 * 3.0, (j, val)
        assert 0 < err[0] < 0.05 * 3.0


def test_too_short_a_record_gives_no_component():
    y = np.random.default_rng(0).standard_normal((12, 3))
    val, err = roving_components(y, FS, 2, 10.0, 0.01, np.array([1.0, 0.5]))
    assert np.isnan(val).all() and np.isnan(err).all()
