"""Responses of a model whose stiffness (or damping) factor changes within an event, segment by segment.

A structure that softens as it shakes harder changes within an earthquake: softer in the strong
motion, recovering after it. One factor per event (:mod:`.td_model`) follows that only on average.
Here one column of the parameter row (the stiffness or the damping factor of :class:`.td_model.FactorModel`)
takes a value per *segment* of an event (a fraction of a second), and the system is linear within a
segment: the exact first-order-hold step (:func:`shm_ros.core.response.discretize_foh`; many at once by
:func:`shm_ros.core.response.discretize.discretize_foh_batch`) of the segment's model carries the state across.

**The approximation that makes it affordable.** An event has hundreds of segments and every
parameter draw its own values, so one matrix exponential per segment is too many. The step matrices
``Phi, G1, G2`` (and ``C, D``) are analytic in the factor; per draw they are computed exactly at a few
Chebyshev nodes spanning the draw's range of the factor (in ``log`` of it) and interpolated (Lagrange)
to each segment's value. :func:`interpolation_error` measures it against the exact per-segment steps
(``test/test_td_varying.py``: below 1e-7 of the response on the test's events).

The recursion itself is a loop over samples (:func:`shm_ros.core.response.kernels.segment_response`,
compiled: scipy has no time-varying state-space filter, and a draw's step matrices change every segment).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from shm_ros.core.models.base import AffineModel
from shm_ros.core.response import Output, build_state_space, build_state_spaces, discretize_foh
from shm_ros.core.response.discretize import discretize_foh_batch
from shm_ros.core.response.kernels import segment_response

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
    """(B, J, n) Lagrange weights of the nodes (B, n) (in log) at the values ``s`` (B, J), in the
    barycentric form ``l(x) w_i / (x - x_i)`` (a value on a node gets that node's weight exactly)."""
    ln, ls = np.log(nodes), np.log(s)
    n = nodes.shape[1]
    gap = ln[:, :, None] - ln[:, None, :] + np.eye(n)  # (B, n, n), 1 on the diagonal
    w = 1.0 / np.prod(gap, axis=2)  # (B, n)
    d = ls[:, :, None] - ln[:, None, :]  # (B, J, n)
    on = d == 0.0
    d = np.where(on, 1.0, d)
    W = np.prod(d, axis=2, keepdims=True) * w[:, None, :] / d
    hit = on.any(axis=2)
    W[hit] = on[hit]
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
    # draws that differ only where the segments' factor is set (a finite-difference step in a candidate's
    # own parameters) share every node's system: each distinct one is built and discretised once
    at, back = np.unique(at, axis=0, return_inverse=True)
    systems = build_state_spaces(model, at, outputs)
    A, Bm, C, D = (np.stack([getattr(ss, m) for ss in systems]) for m in ("A", "B", "C", "D"))
    Phi, G1, G2 = discretize_foh_batch(A, Bm, dt)
    return NodeSteps(nodes, *(M[back.ravel()].reshape(B, n, *M.shape[1:]) for M in (Phi, G1, G2, C, D)))


def varying_responses(steps: NodeSteps, values: np.ndarray, seg_len: int, u: np.ndarray) -> np.ndarray:
    """Outputs (B, n_outputs, N) from rest of the draws of ``steps`` whose factor takes ``values[:, j]``
    (B, J; inside the nodes' range) in samples ``j * seg_len`` to ``(j + 1) * seg_len`` (the last
    segment to the end); ``u`` (n_inputs, N) as for :func:`shm_ros.core.response.batch.batch_responses`."""
    values = np.atleast_2d(np.asarray(values, float))
    B, n = values.shape[0], steps.nodes.shape[1]
    W = _lagrange(steps.nodes, values)  # (B, J, n)

    def interp(M: np.ndarray) -> np.ndarray:  # (B, n, r, c) at the segments' values: (B, J, r, c)
        return (W @ M.reshape(B, n, -1)).reshape(B, W.shape[1], *M.shape[2:])

    return segment_response(interp(steps.Phi), interp(steps.G1), interp(steps.G2), interp(steps.C),
                            interp(steps.D), u, max(int(seg_len), 1))


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
