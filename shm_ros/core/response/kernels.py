"""Compiled sample loops of the response recursions (numba).

Two recursions run sample by sample and so cannot be vectorised over time:

* :func:`first_order_filters`: many complex first-order filters ``q[k] = p q[k-1] + beta u[k] +
  alpha u[k-1]`` from rest, each with its own pole and weights (the modal route of
  :mod:`shm_ros.core.response.batch`). ``scipy.signal.lfilter`` takes one filter per call: a call
  per pole, draw and input cost ~50 us each, mostly overhead.
* :func:`segment_response`: the first-order-hold state recursion whose matrices change segment by
  segment (:mod:`shm_ros.core.explain.td_varying`). scipy has no time-varying state-space filter;
  in numpy the loop costs a batched 16x16 product per sample (~5 us, mostly call overhead).

Both are plain loops compiled by numba (cached on disk after the first call of a process; the GIL
released, so chunks on threads run in parallel) and give the results of plain loops to round-off
(``test/test_response_kernels.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _filters(pole: np.ndarray, alpha: np.ndarray, beta: np.ndarray, u: np.ndarray, which: np.ndarray,
             re: np.ndarray, im: np.ndarray) -> None:  # pragma: no cover - compiled
    n = u.shape[1]
    for r in range(pole.shape[0]):
        p, a, b = pole[r], alpha[r], beta[r]
        x = u[which[r]]
        q = 0.0j
        re[r, 0] = 0.0
        im[r, 0] = 0.0
        for k in range(1, n):
            q = p * q + b * x[k] + a * x[k - 1]
            re[r, k] = q.real
            im[r, k] = q.imag


def first_order_filters(pole: np.ndarray, alpha: np.ndarray, beta: np.ndarray, u: np.ndarray,
                        which: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Real and imaginary parts, (R, N) each, of R filters ``q[k] = pole q[k-1] + beta u[k] +
    alpha u[k-1]``, ``q[0] = 0``, filter ``r`` driven by the input row ``u[which[r]]`` (``u`` real,
    (m, N)); apart, since the outputs are formed by two real products."""
    pole, alpha, beta = (np.ascontiguousarray(v, dtype=complex).ravel() for v in (pole, alpha, beta))
    u = np.ascontiguousarray(u, dtype=float)
    re = np.empty((pole.size, u.shape[1]))
    im = np.empty_like(re)
    _filters(pole, alpha, beta, u, np.ascontiguousarray(which, dtype=np.int64).ravel(), re, im)
    return re, im


@njit(cache=True, nogil=True)
def _segments(Phi: np.ndarray, G1: np.ndarray, G2: np.ndarray, C: np.ndarray, D: np.ndarray, up: np.ndarray,
              L: int, y: np.ndarray) -> None:  # pragma: no cover - compiled
    B, J, ns = Phi.shape[0], Phi.shape[1], Phi.shape[2]
    m, o = up.shape[0], C.shape[2]
    x = np.zeros(ns)
    xn = np.zeros(ns)
    PT = np.empty((ns, ns))
    for b in range(B):
        x[:] = 0.0
        for j in range(J):
            PT[:, :] = Phi[b, j].T  # column i of Phi contiguous: the step's inner loop vectorises
            Cj, Dj, G1j, G2j = C[b, j], D[b, j], G1[b, j], G2[b, j]
            for k in range(j * L, (j + 1) * L):
                for r in range(o):
                    acc = 0.0
                    for i in range(ns):
                        acc += Cj[r, i] * x[i]
                    for q in range(m):
                        acc += Dj[r, q] * up[q, k]
                    y[b, r, k] = acc
                for i in range(ns):
                    acc = 0.0
                    for q in range(m):
                        acc += G1j[i, q] * up[q, k] + G2j[i, q] * (up[q, k + 1] - up[q, k])
                    xn[i] = acc
                for i in range(ns):
                    xi = x[i]
                    for r in range(ns):
                        xn[r] += PT[i, r] * xi
                x, xn = xn, x


def segment_response(Phi: np.ndarray, G1: np.ndarray, G2: np.ndarray, C: np.ndarray, D: np.ndarray,
                     u: np.ndarray, seg_len: int) -> np.ndarray:
    """Outputs (B, o, N) from rest of the first-order-hold recursion whose matrices change per segment
    of ``seg_len`` samples: for sample ``k`` in segment ``j``,

        y[k] = C_j x[k] + D_j u[k],   x[k+1] = Phi_j x[k] + G1_j u[k] + G2_j (u[k+1] - u[k]),

    the matrices given per draw and segment, (B, J, r, c) each; ``u`` (m, N), held at its last value
    past the end (``J seg_len >= N``)."""
    u = np.atleast_2d(np.asarray(u, dtype=float))
    (B, J), N, L = Phi.shape[:2], u.shape[1], int(seg_len)
    if J * L < N:
        raise ValueError(f"{J} segments of {L} samples do not cover {N} samples")
    up = np.empty((u.shape[0], J * L + 1))
    up[:, :N] = u
    up[:, N:] = u[:, -1:]
    y = np.empty((B, C.shape[2], J * L))
    Phi, G1, G2, C, D = (np.ascontiguousarray(M, dtype=float) for M in (Phi, G1, G2, C, D))
    _segments(Phi, G1, G2, C, D, up, L, y)
    return y[:, :, :N]
