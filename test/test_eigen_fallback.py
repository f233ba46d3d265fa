"""Every fallback of ``shm_ros.core.eigen`` (LAPACK entry points missing, Hessenberg reduction or
QR iteration failing, inverse iteration not converging) gives the eigenpairs of the ORIGINAL
matrix, checked against ``scipy.linalg.eig`` on badly scaled matrices where balancing matters."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
from test_identify_eigen import _state_matrix

from shm_ros.core import eigen, ssi


def _matrix(n: int, seed: int, balance: bool) -> np.ndarray:
    """Badly scaled when it is to be balanced; well scaled otherwise (as the state matrices of
    identify, which are built in an orthonormal basis and not balanced)."""
    a = _state_matrix(np.random.default_rng(seed), n, scaled=balance)
    if balance:  # the test means something only if balancing really changes the basis
        scale = sla.matrix_balance(a, permute=False, separate=True)[1][0]
        assert scale.max() / scale.min() > 100
    return a


def _check_against_scipy(a: np.ndarray, ev: eigen.Eigenvalues) -> None:
    """Same spectrum as scipy; the vectors of chosen eigenvalues are eigenvectors of ``a``
    (residual) and the same ones scipy finds (MAC ~ 1, i.e. equal up to a complex scale)."""
    w, v = sla.eig(a)
    assert np.abs(ev.values[:, None] - w[None, :]).min(axis=1).max() < 1e-8 * np.abs(w).max()
    pos = np.flatnonzero(ev.values.imag > 0)
    which = np.concatenate([pos[:4], np.flatnonzero(ev.values.imag == 0)[:1]])
    assert which.size >= 2
    x = eigen.eigenvectors(ev, which)
    lam = ev.values[which]
    res = np.linalg.norm(a @ x - x * lam[None, :], axis=0)
    assert np.all(res <= 1e-8 * np.linalg.norm(a) * np.linalg.norm(x, axis=0)), res
    ref = v[:, np.abs(lam[:, None] - w[None, :]).argmin(axis=1)]
    mac = np.abs(np.sum(ref.conj() * x, axis=0)) ** 2 / (
        np.sum(np.abs(ref) ** 2, axis=0) * np.sum(np.abs(x) ** 2, axis=0))
    assert np.all(mac > 1 - 1e-6), mac


def _fail(*_args, **_kwargs):
    raise AssertionError("not reached")


@pytest.fixture(params=[True, False], ids=["balanced", "unbalanced"])
def balance(request) -> bool:
    return request.param


@pytest.mark.parametrize("n", [5, 40])
def test_without_the_lapack_entry_points(monkeypatch, balance, n):
    monkeypatch.setattr(eigen, "AVAILABLE", False)
    monkeypatch.setattr(eigen, "_qr_eigenvalues", _fail)  # the fast path must not run at all
    a = _matrix(n, n, balance)
    ev = eigen.eigenvalues(a, balance=balance)
    assert ev.dense_vectors is not None
    _check_against_scipy(a, ev)


@pytest.mark.parametrize("n", [5, 40, 160])
def test_when_the_qr_iteration_does_not_converge(monkeypatch, balance, n):
    calls: list[bool] = []

    def no_convergence(h: np.ndarray, small: bool):
        calls.append(small)
        return np.zeros(h.shape[0]), np.zeros(h.shape[0]), 1

    monkeypatch.setattr(eigen, "_qr_eigenvalues", no_convergence)
    a = _matrix(n, n + 1, balance)
    ev = eigen.eigenvalues(a, balance=balance)
    assert calls and ev.dense_vectors is not None  # the fallback did run
    _check_against_scipy(a, ev)


@pytest.mark.parametrize("n", [5, 40])
def test_when_the_hessenberg_reduction_fails(monkeypatch, balance, n):
    real = sla.lapack.dgehrd

    def failing(x, *args, **kwargs):
        refl, tau, _ = real(x, *args, **kwargs)
        return refl, tau, -1

    monkeypatch.setattr(sla.lapack, "dgehrd", failing)
    a = _matrix(n, n + 2, balance)
    ev = eigen.eigenvalues(a, balance=balance)
    assert ev.dense_vectors is not None
    _check_against_scipy(a, ev)


@pytest.mark.skipif(not eigen.AVAILABLE, reason="needs the LAPACK entry points")
@pytest.mark.parametrize("n", [6, 40])
def test_when_inverse_iteration_does_not_converge(monkeypatch, balance, n):
    """dhsein flags every vector as failed (and leaves garbage): all are redone densely from H
    and still taken back through Q and the balancing to the basis of ``a``."""
    assert eigen._HSEIN is not None
    real = eigen._call

    def flag_all(fn, *args):
        real(fn, *args)
        if fn is eigen._HSEIN:
            vr, ifailr = args[11], args[17]
            vr[:] = 1.0
            ifailr[:] = 1

    monkeypatch.setattr(eigen, "_call", flag_all)
    a = _matrix(n, n + 3, balance)
    ev = eigen.eigenvalues(a, balance=balance)
    assert ev.dense_vectors is None  # the fast path, with its own fallback for the vectors
    _check_against_scipy(a, ev)


def _diagram_input() -> np.ndarray:
    rng = np.random.default_rng(7)
    out = np.zeros((6000, 3))
    for f, phi in [(1.3, [1, .6, .3]), (4.1, [-.5, .2, 1])]:
        t = np.arange(6000) / 50.0
        out += np.sin(2 * np.pi * f * t + rng.uniform(0, 6))[:, None] * np.array(phi)[None]
    return out + 0.3 * rng.standard_normal(out.shape)


def test_the_diagram_of_identify_is_the_same_without_the_lapack_entry_points(monkeypatch):
    """The path identify uses (unbalanced state matrices of every order, shapes of chosen poles):
    same poles and shapes when everything goes through ``scipy.linalg.eig``."""
    model = ssi.ssi_cov(_diagram_input(), 50.0, 10, 20)
    fast = ssi.poles_all_orders(model, shapes_for=(0.01, 0.05))
    monkeypatch.setattr(eigen, "AVAILABLE", False)
    dense = ssi.poles_all_orders(model, shapes_for=(0.01, 0.05))
    assert np.array_equal(fast.order, dense.order)
    assert np.allclose(fast.frequency_hz, dense.frequency_hz, rtol=1e-9)
    has = np.isfinite(fast.shape[:, 0])
    assert has.any() and np.array_equal(has, np.isfinite(dense.shape[:, 0]))
    mac = np.abs(np.sum(fast.shape[has].conj() * dense.shape[has], axis=1)) ** 2
    assert np.all(mac > 1 - 1e-8)
