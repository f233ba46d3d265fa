"""The IIRS fixed-point iteration on a batch, compiled (numba).

Inside a likelihood the batch is a sampler's walkers (a dozen) and the reduced model a few DOFs,
so each iteration in numpy is some thirty calls on (B, 4, 4) stacks that each cost more in call
overhead than in arithmetic (about 0.25 ms per iteration); here one call runs every iteration.

The results are those of the numpy iteration bit for bit, not only to round-off: a sampler's
chains depend on every decision of the iteration (when a member has converged, which members jump),
and a decision taken on a last-bit difference would send the chains elsewhere. So the products and
solves are the same BLAS and LAPACK calls (numba's ``np.dot`` and ``np.linalg.solve``), sums add in
numpy's order (:func:`_pairwise_sum`), and elementwise steps keep numpy's operand order
(``test/test_reduction_iirs.py`` compares the two).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_BLOCK = 128  # numpy's pairwise-summation block (PW_BLOCKSIZE)


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
def _squares_sum(a: np.ndarray) -> float:  # pragma: no cover
    """``np.sum(a * a)`` of a C-contiguous matrix."""
    flat = a.ravel()
    return _pairwise_sum(flat * flat, 0, flat.size, 1)


@njit(cache=True, nogil=True, error_model="numpy")
def iterate(Mmm: np.ndarray, Mms: np.ndarray, Mss: np.ndarray, tG: np.ndarray, Kss_inv: np.ndarray,
            KG: np.ndarray, Kss: np.ndarray, t: np.ndarray, KR: np.ndarray, tol_trace: float,
            max_iter: int, accelerate: bool, r_max: float, active: np.ndarray
            ) -> tuple[bool, int, float]:  # pragma: no cover - compiled
    """The iteration of :func:`shm_ros.core.models.reduction._iterate` on a batch: ``t`` (B, s, m)
    and ``KR`` (B, m, m) are updated in place; ``active`` (B,) is left True for the members that did
    not converge. Returns (all converged, iterations, largest relative change of the last check)."""
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
            P[b] = Mms[b].T + np.dot(Mss[b], t[b])
            MR = (Mmm[b] + np.dot(Mms[b], t[b])) + np.dot(t[b].T, P[b])
            if np.all(np.isfinite(MR)) and np.all(np.isfinite(KR[b])):
                D[b] = np.linalg.solve(MR, KR[b])
            else:  # numpy's solve passes NaN on (numba's would raise)
                D[b] = np.nan
            tr[b] = _pairwise_sum(D[b].ravel(), 0, m, m + 1)
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
                return True, it, change
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
            Y[b] = np.dot(P[b], D[b])
            d[b] = np.dot(Kss_inv[b], Y[b])
            step[b] = (tG[b] + d[b]) - t[b]
            if accelerate and have_step_prev:
                r[b] = math.sqrt(_squares_sum(step[b]) / _squares_sum(step_prev[b]))
        if accelerate and have_step_prev:
            if it % 3 == 0 and have_r_prev:
                for b in range(nb):
                    if active[b]:
                        rb = r[b]
                        jumped[b] = math.isfinite(rb) and rb < r_max and abs(rb - r_prev[b]) < 0.02 * rb + 1e-3
                        any_jumped = any_jumped or jumped[b]
            have_r_prev = True
            r_prev[:] = r
        for b in range(nb):
            if not active[b]:
                continue
            if any_jumped:
                # members in a clean geometric regime jump to the limit of the series,
                # t + step / (1 - r); in the same batch the others step by t + step / 1
                t[b] = t[b] + step[b] / (1.0 - (r[b] if jumped[b] else 0.0))
                d[b] = t[b] - tG[b]
                KR[b] = KG[b] + np.dot(d[b].T, np.dot(Kss[b], d[b]))
            else:
                t[b] = tG[b] + d[b]
                KR[b] = KG[b] + np.dot(d[b].T, Y[b])
            step_prev[b] = step[b]
        have_step_prev = True
    return False, it, change_max
