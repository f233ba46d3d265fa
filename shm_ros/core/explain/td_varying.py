"""Responses of a model whose stiffness (or damping) factor changes within an event, segment by segment.

A structure that softens as it shakes harder changes within an earthquake: softer in the strong
motion, recovering after it. One factor per event (:mod:`.td_model`) follows that only on average.
Here one column of the parameter row (the stiffness or the damping factor of :class:`.td_model.FactorModel`)
takes a value per *segment* of an event (a fraction of a second), and the system is linear within a
segment: the exact first-order-hold step (:func:`shm_ros.core.response.discretize_foh`) of the segment's
model carries the state across.

**The approximation that makes it affordable.** An event has hundreds of segments and every
parameter draw its own values, so one matrix exponential per segment is too many. The step matrices
``Phi, G1, G2`` (and ``C, D``) are analytic in the factor; per draw they are computed exactly at a few
Chebyshev nodes spanning the draw's range of the factor (in ``log`` of it) and interpolated (Lagrange)
to each segment's value. :func:`interpolation_error` measures it against the exact per-segment steps
(``test/test_td_varying.py``: below 1e-7 of the response on the test's events).

The recursion itself is a loop over samples, batched over the draws (numpy, no compiled helper: scipy
has no time-varying state-space filter, and a draw's step matrices change every segment).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from shm_ros.core.models.base import AffineModel
from shm_ros.core.response import Output, build_state_space, build_state_spaces, discretize_foh

MAX_NODES = 24
NODE_GRID = 0.05  # the nodes' range is snapped to multiples of this in ln(factor)


def n_nodes(ratio: float) -> int:
    """Chebyshev nodes for a factor range ``hi / lo`` (interpolation error well below 1e-7 of the
    response up to a factor of 10 in stiffness, :func:`interpolation_error`)."""
    return int(min(MAX_NODES, 4 + np.ceil(4.0 * np.log(max(ratio, 1.0)))))


def _nodes(lo: np.ndarray, hi: np.ndarray, n: int) -> np.ndarray:
    """(B, n) Chebyshev nodes in log between ``lo`` and ``hi`` (B,)."""
    x = np.cos((2 * np.arange(n) + 1) * np.pi / (2 * n))
    a, b = np.log(lo), np.log(hi)
    return np.exp(0.5 * (a + b)[:, None] + 0.5 * (b - a)[:, None] * x[None, :])


def _lagrange(nodes: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(B, J, n) Lagrange weights of the nodes (B, n) (in log) at the values ``s`` (B, J)."""
    ln, ls = np.log(nodes), np.log(s)
    n = nodes.shape[1]
    W = np.ones((*s.shape, n))
    for i in range(n):
        for j in range(n):
            if i != j:
                W[:, :, i] *= (ls - ln[:, j:j + 1]) / (ln[:, i:i + 1] - ln[:, j:j + 1])
    return W


@dataclass
class NodeSteps:
    """Per draw: the factor's Chebyshev nodes (B, n) and the exact steps there, (B, n, ...) each."""

    nodes: np.ndarray
    Phi: np.ndarray
    G1: np.ndarray
    G2: np.ndarray
    C: np.ndarray
    D: np.ndarray


def node_steps(model: AffineModel, rows: np.ndarray, col: int, lo: np.ndarray, hi: np.ndarray, dt: float,
               outputs: Sequence[Output]) -> NodeSteps:
    """Exact steps of ``rows`` (B, d) with column ``col`` at nodes spanning ``lo``-``hi`` (B,): one set
    serves every event of a draw sampled at ``dt``."""
    rows = np.atleast_2d(np.asarray(rows, float))
    # the range snapped outwards to a grid in log (steps of NODE_GRID): draws a finite-difference step
    # apart then share their nodes, so the interpolation error (~1e-10) does not add noise to gradients
    lo = np.exp(np.floor(np.log(np.asarray(lo, float)) / NODE_GRID) * NODE_GRID)
    hi = np.exp(np.ceil(np.log(np.maximum(np.asarray(hi, float), lo * (1 + 1e-9))) / NODE_GRID) * NODE_GRID)
    hi = np.where(hi > lo, hi, lo * np.exp(NODE_GRID))
    nodes = _nodes(lo, hi, n_nodes(float(np.max(hi / lo))))
    B, n = nodes.shape
    at = np.repeat(rows, n, axis=0)
    at[:, col] = nodes.ravel()
    steps = [discretize_foh(ss, dt) for ss in build_state_spaces(model, at, outputs)]
    return NodeSteps(nodes, *(np.stack([getattr(d, m) for d in steps]).reshape(B, n, *getattr(steps[0], m).shape)
                              for m in ("Phi", "G1", "G2", "C", "D")))


def varying_responses(steps: NodeSteps, values: np.ndarray, seg_len: int, u: np.ndarray) -> np.ndarray:
    """Outputs (B, n_outputs, N) from rest of the draws of ``steps`` whose factor takes ``values[:, j]``
    (B, J; inside the nodes' range) in samples ``j * seg_len`` to ``(j + 1) * seg_len`` (the last
    segment to the end); ``u`` (n_inputs, N) as for :func:`shm_ros.core.predict.batch.batch_responses`."""
    values = np.atleast_2d(np.asarray(values, float))
    u = np.atleast_2d(np.asarray(u, float))
    B, N, J = values.shape[0], u.shape[1], values.shape[1]
    W = _lagrange(steps.nodes, values)  # (B, J, n)
    Phi, G1, G2, C, D = (np.einsum("bjk,bk...->bj...", W, M)
                         for M in (steps.Phi, steps.G1, steps.G2, steps.C, steps.D))
    L = max(int(seg_len), 1)
    if J * L < N:
        raise ValueError(f"{J} segments of {L} samples do not cover {N} samples")
    up = np.zeros((u.shape[0], J * L + 1))
    up[:, :N] = u
    up[:, N:] = u[:, -1:]
    du = np.diff(up, axis=1)[:, :J * L].reshape(-1, J, L)
    # drive[b, j, l] = G1 u[k] + G2 (u[k+1] - u[k]), k = j L + l, with the step of segment j
    drive = (np.einsum("bjim,mjl->bjli", G1, up[:, :J * L].reshape(-1, J, L))
             + np.einsum("bjim,mjl->bjli", G2, du))
    n = Phi.shape[2]
    z = np.zeros((B, J, L, n))
    x = np.zeros((B, n, 1))
    for j in range(J):
        P = np.ascontiguousarray(Phi[:, j])
        for k in range(L):
            z[:, j, k] = x[:, :, 0]
            x = np.matmul(P, x)
            x[:, :, 0] += drive[:, j, k]
    y = np.einsum("bjoi,bjli->bjlo", C, z) + np.einsum("bjom,mjl->bjlo", D, up[:, :J * L].reshape(-1, J, L))
    return np.moveaxis(y.reshape(B, J * L, -1)[:, :N], 1, 2)


def exact_varying_response(model: AffineModel, row: np.ndarray, col: int, values: np.ndarray, seg_len: int,
                           u: np.ndarray, dt: float, outputs: Sequence[Output]) -> np.ndarray:
    """The same response with one exact discretisation per segment (slow: the reference)."""
    u = np.atleast_2d(np.asarray(u, float))
    N = u.shape[1]
    J = len(values)
    x = None
    y = np.zeros((len(outputs), N))
    for j in range(J):
        r = np.asarray(row, float).copy()
        r[col] = values[j]
        d = discretize_foh(build_state_space(model, r, outputs), dt)
        if x is None:
            x = np.zeros(d.Phi.shape[0])
        k0, k1 = j * seg_len, (N if j == J - 1 else min((j + 1) * seg_len, N))
        for k in range(k0, k1):
            y[:, k] = d.C @ x + d.D @ u[:, k]
            if k + 1 < N:
                x = d.Phi @ x + d.G1 @ u[:, k] + d.G2 @ (u[:, k + 1] - u[:, k])
    return y


def interpolation_error(model: AffineModel, row: np.ndarray, col: int, values: np.ndarray, seg_len: int,
                        u: np.ndarray, dt: float, outputs: Sequence[Output]) -> float:
    """max |interpolated - exact| / max |exact| of the response (:func:`exact_varying_response`)."""
    v = np.asarray(values, float)
    steps = node_steps(model, np.atleast_2d(row), col, np.array([v.min()]), np.array([v.max()]), dt, outputs)
    y = varying_responses(steps, v[None, :], seg_len, u)[0]
    ref = exact_varying_response(model, row, col, values, seg_len, u, dt, outputs)
    return float(np.max(np.abs(y - ref)) / max(float(np.max(np.abs(ref))), 1e-300))
