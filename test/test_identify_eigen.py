"""Eigenvalues first, eigenvectors of chosen poles later (``shm_ros.core.eigen``), and the
diagram that uses it: same poles, same shapes and same picks as a full ``scipy.linalg.eig``."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.signal as sig

from shm_ros.core import eigen, ssi


def _state_matrix(rng: np.random.Generator, n: int, scaled: bool) -> np.ndarray:
    """A non-normal real matrix with lightly damped complex pairs and a real eigenvalue; if
    ``scaled``, badly scaled (as the state matrix of an unbalanced realization)."""
    k = n // 2
    r = rng.uniform(0.6, 0.999, k)
    th = rng.uniform(0.02, 3.0, k)
    blocks = [np.array([[ri * np.cos(t), -ri * np.sin(t)], [ri * np.sin(t), ri * np.cos(t)]])
              for ri, t in zip(r, th)]
    if n % 2:
        blocks.append(np.array([[rng.uniform(-0.5, 0.5)]]))
    d = sla.block_diag(*blocks)
    t = np.eye(n) + 0.3 * rng.standard_normal((n, n)) / np.sqrt(n)
    s = np.diag(10.0 ** rng.uniform(-3, 3, n) if scaled else np.ones(n))
    return s @ t @ d @ np.linalg.inv(t) @ np.linalg.inv(s)


@pytest.mark.parametrize("n", [2, 3, 17, 60, 101, 160])
@pytest.mark.parametrize("balance", [True, False])
def test_eigenvalues_and_selected_vectors_match_a_full_decomposition(n, balance):
    rng = np.random.default_rng(n)
    a = _state_matrix(rng, n, scaled=balance)
    ev = eigen.eigenvalues(a, balance=balance)
    ref = np.linalg.eigvals(a)
    # same spectrum (each value matched to its nearest reference value)
    d = np.abs(ev.values[:, None] - ref[None, :]).min(axis=1)
    assert np.all(d < 1e-8 * max(1.0, np.abs(ref).max()))
    # pairs stored positive imaginary part first
    pos = np.flatnonzero(ev.values.imag > 0)
    assert np.allclose(ev.values[pos + 1], np.conj(ev.values[pos]))
    which = pos[::2] if pos.size > 1 else pos
    real = np.flatnonzero(ev.values.imag == 0)[:2]
    which = np.concatenate([which, real])
    v = eigen.eigenvectors(ev, which)
    assert v.shape == (n, which.size)
    res = np.linalg.norm(a @ v - v * ev.values[which][None, :], axis=0)
    assert np.all(res <= 1e-7 * np.linalg.norm(a) * np.linalg.norm(v, axis=0))
    assert eigen.eigenvectors(ev, np.array([], int)).shape == (n, 0)


def test_lapack_entry_points_are_found():
    # the fast path must be the one that runs on the supported scipy
    assert eigen.AVAILABLE


def test_diagram_with_lazy_shapes_equals_the_full_one():
    """Shapes only for poles with a neighbour at the adjacent order: every such pole gets the
    same shape (up to phase) as when all shapes are computed, and the stability-relevant poles
    are exactly those."""
    rng = np.random.default_rng(4)
    fs, n = 50.0, 30000
    out = np.zeros((n, 4))
    for f, z, phi in [(1.3, 0.02, [1, .7, .4, .2]), (4.1, 0.015, [-.6, .1, .8, 1]),
                      (7.7, 0.03, [.3, -.9, .5, -.2])]:
        w = 2 * np.pi * f
        b, a = sig.cont2discrete(([1.0], [1.0, 2 * z * w, w * w]), 1 / fs, method="zoh")[:2]
        out += sig.lfilter(np.ravel(b), a, rng.standard_normal(n))[:, None] * np.array(phi)[None]
    out += 0.2 * out.std(axis=0) * rng.standard_normal(out.shape)
    model = ssi.ssi_cov(out, fs, 20, 40)
    full = ssi.poles_all_orders(model)
    lazy = ssi.poles_all_orders(model, shapes_for=(0.01, 0.05))
    assert np.array_equal(full.order, lazy.order)
    assert np.allclose(full.frequency_hz, lazy.frequency_hz, rtol=1e-12)
    has = np.isfinite(lazy.shape[:, 0])
    assert 0 < has.sum() < len(lazy)
    mac = np.abs(np.sum(full.shape[has].conj() * lazy.shape[has], axis=1)) ** 2
    assert np.all(mac > 1 - 1e-8)
    # the two-A partners agree wherever the lazy diagram has a shape
    ok = has & np.isfinite(full.frequency_b_hz)
    close = np.abs(lazy.frequency_b_hz[ok] - full.frequency_b_hz[ok]) <= 1e-9 * full.frequency_hz[ok]
    assert close.mean() > 0.95
