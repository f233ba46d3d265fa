"""Responses of many parameter draws to one input record, with :mod:`shm_ros.core.response`.

The draws of a chunk are discretised together in modal coordinates: one batched eigen-decomposition
``A = V diag(s) V^-1`` of their continuous state matrices, after which the exact first-order-hold
step (:func:`shm_ros.core.response.discretize_foh`) of every pole is a scalar formula,

    q[k+1] = e^{z} q[k] + h (phi1(z) - phi2(z)) b u[k] + h phi2(z) b u[k+1],   z = s h,
    phi1(z) = (e^z - 1) / z,   phi2(z) = (e^z - 1 - z) / z^2,   b = V^-1 B,

and each pole (one of each conjugate pair) is one compiled first-order filter
(:func:`shm_ros.core.response.kernels.first_order_filters`). A draw whose eigenbasis is
ill-conditioned (a Jordan block of support integrator states) falls back to
:func:`shm_ros.core.response.simulate` on the matrix-exponential step.

Chunks may run on ``threads`` threads (the products, eigenproblems and filters release the GIL). Callers
should hold BLAS to one thread (``single_blas_thread``, as :func:`.predict.predict_event` does):
the matrices are small, and a BLAS thread pool only waits on them (on a loaded machine, a hundred
times slower). Results do not depend on ``threads`` or on the chunk size.

Several records (events) at once (:func:`record_responses`): the eigen-decompositions do not depend
on the input or the sample interval, so every record's draws are assembled and decomposed in one
batch, each distinct parameter row once (:class:`_Modal`), and only the filters run per record.
"""

from __future__ import annotations

import contextlib
from collections import deque
from collections.abc import Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from shm_ros.core.models.base import AffineModel
from shm_ros.core.response import Output, StateSpace, build_state_spaces, discretize_foh, simulate
from shm_ros.core.response.kernels import first_order_filters
from shm_ros.core.structure import InputSpec

_MAX_COND = 1e8  # eigenbasis condition number up to which the modal route keeps ~1e-8 accuracy
_SERIES = 1e-2  # |z| below which phi1, phi2 come from their Taylor series (no cancellation)


def batch_responses(model: AffineModel, thetas: np.ndarray, u: np.ndarray, dt: float,
                    outputs: Sequence[Output], inputs: Sequence[InputSpec] | None = None,
                    chunk: int = 32, threads: int = 1) -> Iterator[tuple[int, np.ndarray]]:
    """Yield ``(first draw index, Y)`` with Y (B, n_outputs, N) for successive chunks of ``thetas``
    (n_draws, d), in order, from rest; ``u`` (n_inputs, N) are the input records (gains applied by
    the model). At most ``threads + 1`` chunks are held at once."""
    thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
    u = np.atleast_2d(np.asarray(u, dtype=float))
    ins = list(model.inputs if inputs is None else inputs)
    step = max(1, int(chunk))
    starts = list(range(0, thetas.shape[0], step))

    def work(a: int) -> np.ndarray:
        return _run_chunk(build_state_spaces(model, thetas[a:a + step], outputs, ins), u, dt)

    if threads <= 1 or len(starts) <= 1:
        for a in starts:
            yield a, work(a)
        return
    with ThreadPoolExecutor(max_workers=int(threads)) as pool:
        queue: deque[tuple[int, Future[np.ndarray]]] = deque()
        for a in starts:
            queue.append((a, pool.submit(work, a)))
            if len(queue) > threads:
                b, f = queue.popleft()
                yield b, f.result()
        while queue:
            b, f = queue.popleft()
            yield b, f.result()


def record_responses(model: AffineModel, thetas: Sequence[np.ndarray], records: Sequence[tuple[np.ndarray, float]],
                     outputs: Sequence[Output], chunk: int = 32) -> Iterator[tuple[int, int, np.ndarray]]:
    """Yield ``(record, first draw index, Y)`` for the draws ``thetas[r]`` (n_r, d) of each record
    ``records[r] = (u, dt)``, record by record, in chunks of ``chunk`` draws, as
    :func:`batch_responses` per record. The state spaces of every record's draws are built in one
    batch, each distinct parameter row once: several records at the same parameters (a calibration
    on several events) or at rows that differ per record (an effect that changes between events) cost
    one assembly instead of one per record, which on small models is most of a response's cost."""
    rows = [np.atleast_2d(np.asarray(t, dtype=float)) for t in thetas]
    if not rows:
        return
    unique, back = np.unique(np.vstack(rows), axis=0, return_inverse=True)
    modal = _Modal.of(build_state_spaces(model, unique, outputs, list(model.inputs)))
    starts = np.cumsum([0] + [r.shape[0] for r in rows])
    step = max(1, int(chunk))
    for k, (u, dt) in enumerate(records):
        u = np.atleast_2d(np.asarray(u, dtype=float))
        mine = back.ravel()[starts[k]:starts[k + 1]]
        for a in range(0, mine.size, step):
            yield k, a, modal.respond(mine[a:a + step], u, dt)


def single_blas_thread() -> contextlib.AbstractContextManager:
    """One BLAS thread (``threadpoolctl``) while in the context; the numbers are the same either way."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - pinned in requirements/base.txt
        return contextlib.nullcontext()
    return threadpool_limits(1, "blas")


def phi12(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``phi1(z) = (e^z - 1)/z`` and ``phi2(z) = (e^z - 1 - z)/z^2`` (limits 1 and 1/2 at 0)."""
    z = np.asarray(z, dtype=complex)
    small = np.abs(z) < _SERIES
    zs = np.where(small, 1.0, z)
    em1 = np.expm1(zs)
    p1 = em1 / zs
    p2 = (em1 - zs) / zs ** 2
    if small.any():
        w = z[small]
        # Taylor series: terms up to z^6 leave < 1e-17 at |z| < 1e-2
        s1 = np.zeros_like(w)
        s2 = np.zeros_like(w)
        fact = 1.0
        for k in range(7):
            fact *= k + 1  # (k + 1)!
            s1 += w ** k / fact
            s2 += w ** k / (fact * (k + 2))
        p1[small] = s1
        p2[small] = s2
    return p1, p2


@dataclass
class _Modal:
    """Systems in modal coordinates, independent of the sample interval and of the input: per system
    (leading axis B) its direct term, whether its eigenbasis is well conditioned (else the fallback),
    and, for those, the kept poles (one of each conjugate pair first, ``w`` 2 for a pair, 1 for a real
    pole, 0 for the dropped rest), their input weights ``V^-1 B`` and output rows ``C V w``."""

    systems: list[StateSpace]
    D: np.ndarray  # (B, o, m)
    good: np.ndarray  # (B,) bool
    lam: np.ndarray  # (B, nk) complex
    w: np.ndarray  # (B, nk)
    bt: np.ndarray  # (B, nk, m) complex
    CV: np.ndarray  # (B, o, nk) complex

    @classmethod
    def of(cls, systems: list[StateSpace]) -> _Modal:
        B = len(systems)
        D = np.stack([s.D for s in systems])
        A = np.stack([s.A for s in systems])
        n, m, o = A.shape[1], D.shape[2], D.shape[1]
        if n == 0:
            return cls(systems, D, np.zeros(B, bool), np.zeros((B, 0), complex), np.zeros((B, 0)),
                       np.zeros((B, 0, m), complex), np.zeros((B, o, 0), complex))
        lam, V = np.linalg.eig(A)
        good = np.linalg.cond(V) < _MAX_COND
        Bm = np.stack([s.B for s in systems])
        C = np.stack([s.C for s in systems])
        # a real system's poles are real or conjugate pairs, whose modal responses are conjugate too:
        # filter one pole of each pair and count it twice
        scale = np.maximum(1.0, np.max(np.abs(lam), axis=1, keepdims=True))
        real = np.abs(lam.imag) <= 1e-9 * scale
        weight = np.where(real, 1.0, np.where(lam.imag > 0, 2.0, 0.0))
        order = np.argsort(weight == 0.0, axis=1, kind="stable")  # kept poles first
        keep = order[:, :int(np.max(np.sum(weight > 0, axis=1)))]
        w = np.take_along_axis(weight, keep, 1)
        bt = np.zeros((B, keep.shape[1], m), complex)
        CV = np.zeros((B, o, keep.shape[1]), complex)
        if good.any():
            g = np.flatnonzero(good)
            bt[g] = np.take_along_axis(np.linalg.solve(V[g], Bm[g].astype(complex)), keep[g][:, :, None], 1)
            CV[g] = np.take_along_axis(C[g].astype(complex) @ V[g], keep[g][:, None, :], 2) * w[g][:, None, :]
        return cls(systems, D, good, np.take_along_axis(lam, keep, 1), w, bt, CV)

    def respond(self, rows: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
        """Outputs (len(rows), o, N) from rest of the systems ``rows`` under ``u`` (m, N) sampled at
        ``dt``: the exact first-order-hold step of every kept pole (module docstring)."""
        rows = np.asarray(rows, dtype=int)
        m, N = u.shape
        out = self.D[rows] @ u  # direct terms, (b, o, N)
        if self.lam.shape[1] == 0 or N < 2:
            return out
        good = self.good[rows]
        for b in np.flatnonzero(~good):
            out[b] = simulate(discretize_foh(self.systems[rows[b]], dt), u)
        idx = np.flatnonzero(good)
        if idx.size == 0:
            return out
        r = rows[idx]
        nk = int(np.max(np.sum(self.w[r] > 0, axis=1)))  # the most kept poles of these systems
        w_k, lam_k, bt, CV = self.w[r, :nk], self.lam[r, :nk], self.bt[r, :nk], self.CV[r][:, :, :nk]
        z = lam_k * dt
        p1, p2 = phi12(z)
        pole = np.exp(z)
        beta = (dt * p2)[:, :, None] * bt  # weight of u[k+1]
        alpha = (dt * (p1 - p2))[:, :, None] * bt  # weight of u[k]
        # one filter per system, kept pole and input (rows in that order: (b, j) major, input i minor)
        bj = np.nonzero(w_k)
        re, im = first_order_filters(np.repeat(pole[bj], m), alpha[bj].ravel(), beta[bj].ravel(), u,
                                     np.tile(np.arange(m), bj[0].size))
        Qre = np.zeros((idx.size, nk, m, N))
        Qim = np.zeros((idx.size, nk, m, N))
        Qre[bj], Qim[bj] = re.reshape(-1, m, N), im.reshape(-1, m, N)
        coef = np.repeat(CV, m, axis=2)  # (b, o, nk m): the same output row for every input
        y = coef.real @ Qre.reshape(idx.size, nk * m, N)
        y -= coef.imag @ Qim.reshape(idx.size, nk * m, N)
        if idx.size == rows.size:
            out += y
        else:
            out[idx] += y
        return out


def _run_chunk(systems: list[StateSpace], u: np.ndarray, dt: float) -> np.ndarray:
    return _Modal.of(systems).respond(np.arange(len(systems)), np.atleast_2d(u), dt)
