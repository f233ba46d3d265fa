"""The compiled sample loops (:mod:`shm_ros.core.response.kernels`) against the loops they replace:
``scipy.signal.lfilter`` per filter, and the numpy recursion batched over draws."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from shm_ros.core.response.kernels import first_order_filters, segment_response


def test_first_order_filters_equal_lfilter_from_rest():
    rng = np.random.default_rng(3)
    R, m, N = 9, 3, 500
    pole = 0.99 * np.exp(1j * rng.uniform(0, np.pi, R)) * rng.uniform(0.5, 1.0, R)
    alpha = rng.normal(size=R) + 1j * rng.normal(size=R)
    beta = rng.normal(size=R) + 1j * rng.normal(size=R)
    u = rng.normal(size=(m, N))
    which = rng.integers(0, m, R)
    re, im = first_order_filters(pole, alpha, beta, u, which)
    q = re + 1j * im
    for r in range(R):
        x = u[which[r]]
        ref = lfilter([beta[r], alpha[r]], [1.0, -pole[r]], x, zi=[-beta[r] * x[0]])[0]
        assert abs(q[r, 0]) == 0.0
        np.testing.assert_allclose(q[r], ref, rtol=0, atol=1e-12 * np.max(np.abs(ref)))


def test_segment_response_equals_the_step_by_step_loop():
    rng = np.random.default_rng(4)
    B, J, L, ns, m, o = 3, 7, 5, 6, 2, 3
    N = J * L - 2  # the last segment short: the input is held past the end
    Phi = rng.normal(size=(B, J, ns, ns)) * 0.3
    G1, G2 = rng.normal(size=(2, B, J, ns, m))
    C, D = rng.normal(size=(B, J, o, ns)), rng.normal(size=(B, J, o, m))
    u = rng.normal(size=(m, N))
    y = segment_response(Phi, G1, G2, C, D, u, L)
    assert y.shape == (B, o, N)
    for b in range(B):
        x = np.zeros(ns)
        for k in range(N):
            j = k // L
            np.testing.assert_allclose(y[b, :, k], C[b, j] @ x + D[b, j] @ u[:, k], rtol=1e-12, atol=1e-12)
            du = u[:, k + 1] - u[:, k] if k + 1 < N else np.zeros(m)
            x = Phi[b, j] @ x + G1[b, j] @ u[:, k] + G2[b, j] @ du
    with pytest.raises(ValueError, match="do not cover"):
        segment_response(Phi, G1, G2, C, D, rng.normal(size=(m, J * L + 1)), L)
