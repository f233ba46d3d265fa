"""The IIRS fixed-point iteration on a batch, compiled (numba).

Inside a likelihood the batch is a sampler's walkers (a dozen) and the reduced model a few DOFs,
so each iteration in numpy is some thirty calls on (B, 4, 4) stacks that each cost more in call
overhead than in arithmetic (about 0.25 ms per iteration); here one call runs every iteration.

The results are those of the numpy iteration bit for bit, not only to round-off: a sampler's
chains depend on every decision of the iteration (when a member has converged, which members jump),
and a decision taken on a last-bit difference would send the chains elsewhere. So the products and
solves are the same BLAS and LAPACK calls (numba's ``np.dot``; LAPACK's ``dgesv`` on column-major
copies, as ``np.linalg.solve`` calls it), sums add in numpy's order (:func:`_pairwise_sum`), and
elementwise steps keep numpy's operand order (``test/test_reduction_iirs.py`` compares the two).
``dgesv`` is scipy's, called directly rather than through numba's ``np.linalg.solve`` (which alone
takes some ten seconds to compile), and elementwise steps are written as loops, not array
expressions: the module compiles in a few seconds on first use and is cached on disk.
"""

from __future__ import annotations

import math
from typing import Any

import llvmlite.binding as llvm
import numpy as np
from numba import njit, types
from numba.extending import get_cython_function_address

SINGULAR = -1  # status of :func:`iterate`: a reduced mass matrix was exactly singular
_BLOCK = 128  # numpy's pairwise-summation block (PW_BLOCKSIZE)


# LAPACK's dgesv by a symbol name of our own, bound in every process before compiled code is loaded
llvm.add_symbol("shm_ros_dgesv", get_cython_function_address("scipy.linalg.cython_lapack", "dgesv"))
_dgesv: Any = types.ExternalFunction("shm_ros_dgesv", types.void(*[types.voidptr] * 8))


@njit(cache=True, nogil=True, error_model="numpy")
def _solve(A: np.ndarray, B: np.ndarray, out: np.ndarray) -> int:  # pragma: no cover - compiled
    """``out = A^-1 B`` as ``np.linalg.solve`` computes it (dgesv on column-major copies); returns
    LAPACK's info (> 0: A is exactly singular)."""
    n, k = A.shape[0], B.shape[1]
    a = np.empty((n, n))  # a[j, i] = A[i, j]: A in column-major order
    b = np.empty((k, n))
    for i in range(n):
        for j in range(n):
            a[j, i] = A[i, j]
        for j in range(k):
            b[j, i] = B[i, j]
    pivots = np.empty(n, dtype=np.int32)
    ints = np.array([n, k, n, n, 0], dtype=np.int32)  # n, nrhs, lda, ldb, info
    _dgesv(ints[0:].ctypes, ints[1:].ctypes, a.ctypes, ints[2:].ctypes, pivots.ctypes, b.ctypes,
           ints[3:].ctypes, ints[4:].ctypes)
    for i in range(n):
        for j in range(k):
            out[i, j] = b[j, i]
    return ints[4]


@njit(cache=True, nogil=True, error_model="numpy")
def _block_sum(v: np.ndarray, start: int, n: int, stride: int) -> float:  # pragma: no cover
    """numpy's pairwise sum of at most ``_BLOCK`` values: eight running sums, then a tree."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += v[start + i * stride]
        return res
    r = np.empty(8)
    for j in range(8):
        r[j] = v[start + j * stride]
    i = 8
    while i < n - (n % 8):
        for j in range(8):
            r[j] += v[start + (i + j) * stride]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        res += v[start + i * stride]
        i += 1
    return res


@njit(cache=True, nogil=True, error_model="numpy")
def _pairwise_sum(v: np.ndarray, start: int, n: int, stride: int) -> float:  # pragma: no cover
    """``sum(v[start::stride][:n])`` in the order of numpy's ``add.reduce`` on float64: blocks of
    ``_BLOCK`` summed by :func:`_block_sum`, longer runs halved (at a multiple of 8) and the halves
    added. numpy recurses; this walks the same tree with a stack (numba's disk cache does not keep
    recursive functions)."""
    if n <= _BLOCK:
        return _block_sum(v, start, n, stride)
    starts = np.empty(64, dtype=np.int64)
    counts = np.empty(64, dtype=np.int64)
    state = np.zeros(64, dtype=np.int64)
    values = np.empty(64)
    sp, vp = 1, 0
    starts[0], counts[0] = start, n
    while sp > 0:
        top = sp - 1
        c = counts[top]
        if c <= _BLOCK:
            values[vp] = _block_sum(v, starts[top], c, stride)
            vp += 1
            sp -= 1
            continue
        half = c // 2
        half -= half % 8
        if state[top] == 0:  # the first half
            state[top] = 1
            starts[sp], counts[sp], state[sp] = starts[top], half, 0
            sp += 1
        elif state[top] == 1:  # then the second
            state[top] = 2
            starts[sp], counts[sp], state[sp] = starts[top] + half * stride, c - half, 0
            sp += 1
        else:  # both done: first + second
            values[vp - 2] = values[vp - 2] + values[vp - 1]
            vp -= 1
            sp -= 1
    return values[0]


@njit(cache=True, nogil=True, error_model="numpy")
def _squares_sum(a: np.ndarray, buffer: np.ndarray) -> float:  # pragma: no cover - compiled
    """``np.sum(a * a)`` of a matrix (``buffer``: room for its squares, in C order)."""
    k = 0
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            buffer[k] = a[i, j] * a[i, j]
            k += 1
    return _pairwise_sum(buffer, 0, k, 1)


@njit(cache=True, nogil=True, error_model="numpy")
def iterate(Mmm: np.ndarray, Mms: np.ndarray, Mss: np.ndarray, tG: np.ndarray, Kss_inv: np.ndarray,
            KG: np.ndarray, Kss: np.ndarray, t: np.ndarray, KR: np.ndarray, tol_trace: float,
            max_iter: int, accelerate: bool, r_max: float, active: np.ndarray
            ) -> tuple[int, int, float]:  # pragma: no cover - compiled
    """The iteration of :func:`shm_ros.core.models.reduction._iterate` on a batch: ``t`` (B, s, m)
    and ``KR`` (B, m, m) are updated in place; ``active`` (B,) is left True for the members that did
    not converge. Returns (status: 1 all converged, 0 not, :data:`SINGULAR`; iterations; largest
    relative change of the last check)."""
    nb, s, m = t.shape[0], t.shape[1], t.shape[2]
    P = np.empty((nb, s, m))
    D = np.empty((nb, m, m))
    Y = np.empty((nb, s, m))
    d = np.empty((nb, s, m))
    step = np.empty((nb, s, m))
    step_prev = np.empty((nb, s, m))
    tr = np.empty(nb)
    tr_prev = np.empty(nb)
    r = np.empty(nb)
    r_prev = np.empty(nb)
    done = np.zeros(nb, dtype=np.bool_)
    jumped = np.zeros(nb, dtype=np.bool_)  # members that jumped in the last step
    MR = np.empty((m, m))
    mm1 = np.empty((m, m))
    mm2 = np.empty((m, m))
    sm = np.empty((s, m))
    squares = np.empty(s * m)
    diagonal = np.empty(m)
    have_prev = have_step_prev = have_r_prev = any_jumped = False
    change_max = 0.0
    it = 0
    for it in range(1, max_iter + 1):
        all_done = True
        rel_max = -np.inf
        rel_nan = False
        for b in range(nb):
            if not active[b]:
                continue
            # P = Msm + Mss t;  M_R = Mmm + Mms t + t' P;  D = M_R^-1 K_R
            np.dot(Mss[b], t[b], sm)
            for i in range(s):
                for j in range(m):
                    P[b, i, j] = Mms[b, j, i] + sm[i, j]
            np.dot(Mms[b], t[b], mm1)
            np.dot(t[b].T, P[b], mm2)
            for i in range(m):
                for j in range(m):
                    MR[i, j] = (Mmm[b, i, j] + mm1[i, j]) + mm2[i, j]
            if _solve(MR, KR[b], D[b]) > 0:
                return SINGULAR, it, 0.0
            for i in range(m):
                diagonal[i] = D[b, i, i]
            tr[b] = _pairwise_sum(diagonal, 0, m, 1)
            done[b] = False
            if have_prev:
                rel = abs(tr[b] - tr_prev[b]) / abs(tr[b])
                if math.isnan(rel):
                    rel_nan = True
                elif rel > rel_max:
                    rel_max = rel
                # a change measured across a jump does not count
                done[b] = rel < tol_trace and not (any_jumped and jumped[b])
            all_done = all_done and done[b]
        if have_prev:
            change = math.nan if rel_nan else rel_max
            if all_done:
                return 1, it, change
            change_max = change
        for b in range(nb):
            if active[b]:
                active[b] = not done[b]
                tr_prev[b] = tr[b]
        have_prev = True
        jumped[:] = False
        any_jumped = False
        for b in range(nb):
            if not active[b]:
                continue
            # Y = P D;  d = Kss^-1 Y;  t_new = tG + d
            np.dot(P[b], D[b], Y[b])
            np.dot(Kss_inv[b], Y[b], d[b])
            for i in range(s):
                for j in range(m):
                    step[b, i, j] = (tG[b, i, j] + d[b, i, j]) - t[b, i, j]
            if accelerate and have_step_prev:
                r[b] = math.sqrt(_squares_sum(step[b], squares) / _squares_sum(step_prev[b], squares))
        if accelerate and have_step_prev:
            if it % 3 == 0 and have_r_prev:
                for b in range(nb):
                    if active[b]:
                        rb = r[b]
                        jumped[b] = math.isfinite(rb) and rb < r_max and abs(rb - r_prev[b]) < 0.02 * rb + 1e-3
                        any_jumped = any_jumped or jumped[b]
            have_r_prev = True
            for b in range(nb):
                r_prev[b] = r[b]
        for b in range(nb):
            if not active[b]:
                continue
            if any_jumped:
                # members in a clean geometric regime jump to the limit of the series,
                # t + step / (1 - r); in the same batch the others step by t + step / 1
                f = 1.0 - (r[b] if jumped[b] else 0.0)
                for i in range(s):
                    for j in range(m):
                        t[b, i, j] = t[b, i, j] + step[b, i, j] / f
                        d[b, i, j] = t[b, i, j] - tG[b, i, j]
                np.dot(Kss[b], d[b], sm)
                np.dot(d[b].T, sm, mm1)
            else:
                for i in range(s):
                    for j in range(m):
                        t[b, i, j] = tG[b, i, j] + d[b, i, j]
                np.dot(d[b].T, Y[b], mm1)
            for i in range(m):
                for j in range(m):
                    KR[b, i, j] = KG[b, i, j] + mm1[i, j]
            for i in range(s):
                for j in range(m):
                    step_prev[b, i, j] = step[b, i, j]
        have_step_prev = True
    return 0, it, change_max
