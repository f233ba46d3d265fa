"""The fast leading singular vectors of SSI (``ssi.observability_from``: Gram matrix, tridiagonal
divide and conquer, only the wanted vectors taken back) give the same diagram and the same picked
modes as the full SVD of the block-Hankel matrix, on several windows of the bench's size of
problem (12 channels, 40 block rows, orders 1-100).

Tolerances: pole frequencies 1e-8 relative (the two factorisations differ by rounding only);
picked frequencies 1e-9, damping 1e-7 relative, same poles per mode. The picked *shape* is that of
the cluster's pole nearest the median frequency: with an even number of poles two are equally
near and rounding decides which, so shapes are compared by MAC >= 0.99 (the poles of one mode
agree in shape within the stability criterion, MAC >= 0.98)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
import synthetic_oma as so

from shm_ros.core import ssi
from shm_ros.core.modal import mac_matrix
from shm_ros.core.stabilization import PickingConfig, StabilityConfig, classify, pick_modes

BLOCK_ROWS, MAX_ORDER, FS = 40, 100, 100.0


@pytest.fixture(autouse=True)
def _one_blas_thread():
    with so.single_blas_thread():
        yield


def _diagram(model: ssi.SubspaceModel):
    st = StabilityConfig()
    poles = ssi.poles_all_orders(model, np.arange(1, MAX_ORDER + 1),
                                 match_scale=(st.two_a_freq_tol, st.two_a_damping_tol, st.two_a_mac_min),
                                 shapes_for=(st.freq_tol, st.damping_tol))
    flags = classify(poles, st, FS)
    return poles, flags, pick_modes(poles, flags, PickingConfig())


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_fast_leading_vectors_give_the_picks_of_the_full_svd(seed):
    y, fs, _, _ = so.ambient_record(seed, duration=180.0, fs=FS, noise=0.02, n_sensors=12)
    y = np.asarray(y) - np.mean(y, axis=0)
    fast = ssi.ssi_cov(y, fs, BLOCK_ROWS, MAX_ORDER)
    assert fast.singular_values.size == MAX_ORDER  # the fast path ran (the SVD returns all 480)
    h = ssi.block_hankel_of_correlations(ssi.correlations(y, np.arange(12), 2 * BLOCK_ROWS), BLOCK_ROWS)
    u, s, _ = sla.svd(h)
    ref = ssi.SubspaceModel(u[:, :MAX_ORDER] * np.sqrt(s[:MAX_ORDER]), s, 12, fs, "ssi-cov", BLOCK_ROWS)
    np.testing.assert_allclose(fast.singular_values, s[:MAX_ORDER], rtol=1e-6)
    p_fast, fl_fast, m_fast = _diagram(fast)
    p_ref, fl_ref, m_ref = _diagram(ref)
    # the same diagram: poles of every order and the candidates that enter picking
    assert np.array_equal(p_fast.order, p_ref.order)
    cand = fl_ref.candidates()
    np.testing.assert_allclose(p_fast.frequency_hz[cand], p_ref.frequency_hz[cand], rtol=1e-8)
    assert np.array_equal(fl_fast.candidates(), cand)
    # the same picked modes
    assert len(m_fast) == len(m_ref) >= 4
    for a, b in zip(m_fast, m_ref, strict=True):
        assert a.n_poles == b.n_poles
        assert a.frequency_hz == pytest.approx(b.frequency_hz, rel=1e-9)
        assert a.damping_ratio == pytest.approx(b.damping_ratio, rel=1e-7)
        assert mac_matrix(a.mode_shape_complex[None], b.mode_shape_complex[None])[0, 0] >= 0.99


def test_leading_eigenvectors_of_a_symmetric_matrix():
    """``_leading_eigenvectors`` against a dense eigendecomposition, including a matrix whose
    spectrum spans many decades (as the Gram matrices of SSI do)."""
    rng = np.random.default_rng(3)
    q, _ = np.linalg.qr(rng.standard_normal((60, 60)))
    w = 10.0 ** -np.linspace(0, 14, 60)
    g = (q * w) @ q.T
    vals, vecs = ssi._leading_eigenvectors(np.asfortranarray(g.copy()), 20)
    np.testing.assert_allclose(vals, w[:20], rtol=1e-8)
    assert np.allclose(np.abs(np.sum(vecs * q[:, :20], axis=0)), 1.0, atol=1e-8)
