"""Responses of many parameter draws to one input record, with :mod:`shm_ros.core.response`.

Each draw is discretised once (the exact first-order-hold step of its state space). The draws of a
chunk are then run together in modal coordinates: ``Phi = V diag(lam) V^-1`` per draw (batched
eigen-decomposition), the drive ``V^-1 (G1 u[k] + G2 (u[k+1] - u[k]))`` formed for all draws at
once, and the diagonal recursion ``q[k+1] = lam q[k] + g[k]`` run for every draw and
pole: one compiled first-order filter per pole of each draw (one of each conjugate pair). A
draw whose eigenbasis is ill-conditioned (a Jordan block of support integrator states) falls back
to :func:`shm_ros.core.response.simulate`, the same recursion run step by step.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np
from scipy.signal import lfilter

from shm_ros.core.models.base import AffineModel
from shm_ros.core.response import Output, build_state_space, discretize_foh, simulate
from shm_ros.core.structure import InputSpec

_MAX_COND = 1e8  # as shm_ros.core.response.simulate: the modal route keeps ~1e-8 accuracy below it


def batch_responses(model: AffineModel, thetas: np.ndarray, u: np.ndarray, dt: float,
                    outputs: Sequence[Output], inputs: Sequence[InputSpec] | None = None,
                    chunk: int = 32) -> Iterator[tuple[int, np.ndarray]]:
    """Yield ``(first draw index, Y)`` with Y (B, n_outputs, N) for successive chunks of ``thetas``
    (n_draws, d), from rest; ``u`` (n_inputs, N) are the input records (gains applied by the model)."""
    thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
    u = np.atleast_2d(np.asarray(u, dtype=float))
    ins = list(model.inputs if inputs is None else inputs)
    for a in range(0, thetas.shape[0], max(1, int(chunk))):
        systems = [discretize_foh(build_state_space(model, th, outputs, ins), dt)
                   for th in thetas[a:a + chunk]]
        yield a, _run_chunk(systems, u)


def _run_chunk(systems: list, u: np.ndarray) -> np.ndarray:
    B = len(systems)
    m, N = u.shape
    out = np.stack([s.D for s in systems]) @ u  # direct terms, (B, o, N)
    Phi = np.stack([s.Phi for s in systems])
    n = Phi.shape[1]
    if n == 0 or N < 2:
        return out
    lam, V = np.linalg.eig(Phi)
    good = np.linalg.cond(V) < _MAX_COND
    for b in np.flatnonzero(~good):
        out[b] = simulate(systems[b], u)
    idx = np.flatnonzero(good)
    if idx.size == 0:
        return out
    lam, V = lam[idx], V[idx]
    G1 = np.stack([systems[b].G1 for b in idx])
    G2 = np.stack([systems[b].G2 for b in idx])
    C = np.stack([systems[b].C for b in idx])
    # modal step q[k+1] = lam q[k] + alpha u[k] + beta u[k+1] (the hold's two terms)
    beta = np.linalg.solve(V, G2.astype(complex))  # (b, n, m)
    alpha = np.linalg.solve(V, (G1 - G2).astype(complex))
    # a real system's poles are real or conjugate pairs, whose modal responses are conjugate too:
    # filter one pole of each pair and count it twice
    scale = np.maximum(1.0, np.max(np.abs(lam), axis=1, keepdims=True))
    real = np.abs(lam.imag) <= 1e-9 * scale
    weight = np.where(real, 1.0, np.where(lam.imag > 0, 2.0, 0.0))
    order = np.argsort(weight == 0.0, axis=1, kind="stable")  # kept poles first
    nk = int(np.max(np.sum(weight > 0, axis=1)))
    keep = order[:, :nk]
    lam_k = np.take_along_axis(lam, keep, 1)
    w_k = np.take_along_axis(weight, keep, 1)
    CV = np.take_along_axis(C.astype(complex) @ V, keep[:, None, :], 2) * w_k[:, None, :]  # (b, o, nk)
    # real and imaginary parts of the modal responses, stored apart for two real products
    Qre = np.zeros((idx.size, nk * m, N))
    Qim = np.zeros((idx.size, nk * m, N))
    for b, j in zip(*np.nonzero(w_k), strict=True):
        jj = keep[b, j]
        den = [1.0, -lam_k[b, j]]
        for i in range(m):
            num = [beta[b, jj, i], alpha[b, jj, i]]
            # from rest: q[0] = 0, so the filter's first output beta u[0] is cancelled by its state
            q = lfilter(num, den, u[i], zi=[-num[0] * u[i, 0]])[0]
            Qre[b, j * m + i] = q.real
            Qim[b, j * m + i] = q.imag
    coef = np.repeat(CV, m, axis=2)  # (b, o, nk m): the same output row for every input
    y = coef.real @ Qre
    y -= coef.imag @ Qim
    if idx.size == B:
        out += y
    else:
        out[idx] += y
    return out
