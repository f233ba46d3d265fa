"""Log-frequencies of the paired model modes per window and parameter batch, cheaply.

A candidate turns each window's covariates into factors on parameter groups
(:mod:`.groups`), for a batch of its parameter vectors: B x W eigenproblems per call (a 1,152-window
campaign, hundreds of calls per fit). Two approximations make that affordable, both checked against
the exact eigen-solution of the full model (:meth:`Surrogate.check`, to 1e-4 relative frequency over
the factor ranges the candidates' priors allow):

* one group varies (every candidate of the library): **interpolation in the factor**. Each paired
  mode's log-frequency is a smooth function of the group factor x; it is tabulated once per group by
  the exact eigen-solution at nodes a fixed ``H_NODE`` apart in ln x over the needed range (extended
  on demand) and read by a cubic spline in ln x. The spacing does not depend on the range: extending
  a table keeps its nodes, so a candidate's gain does not depend on which candidates were fitted
  before it (with a fixed number of nodes over the range, a later candidate whose factors reach
  further coarsened an earlier one's table: a freezing knee's gain of 1,187.5 nats became 1,185.0
  when a step's prior had stretched the table from 0.04-3.4 to 0.001-8, and its second evidence
  estimator, run after, disagreed by that much). Modes are followed from the baseline (x = 1) outwards
  node by node by their MAC with the previous node, so a mode keeps its identity when frequencies cross.
* several groups vary together: a **reduced Ritz basis** - the baseline's lowest modes plus, for each
  varying group, the static corrections ``K^-1 dK_g phi`` and ``K^-1 dM_g phi`` of the retained
  modes - M-orthonormalised; the small projected pencils are solved in one batched eigh and modes are
  followed by their MAC with the baseline's paired modes.

``log_frequencies`` returns ``ln f_model`` (B, W, K) of the tracked modes (the model modes
``model_index`` of the baseline pairing).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.interpolate import CubicSpline

from .candidates.base import Modification
from .groups import GroupModel

H_NODE = 0.01  # spacing of a group's table in ln x: cubic spline error ~ h^4, well below 1e-6 in ln f
X_FLOOR, X_CEIL = 1e-3, 1e3  # factors beyond these are not physical for any group


@dataclass
class _Table:
    """Cubic spline of ln f (K,) in u = ln x on nodes ``u0 + i h`` (one of them u = 0)."""

    lo: float
    hi: float
    u0: float
    h: float
    coef: np.ndarray  # (4, n_nodes - 1, K) piecewise cubic coefficients, highest power first
    shapes: np.ndarray  # (n_nodes, dof, K) the followed modes' shapes at the nodes

    def __call__(self, u: np.ndarray) -> np.ndarray:
        # written out and compiled (uniform nodes: the interval is an index computation) because
        # scipy's spline evaluation costs ~20x more on the (B, W) arrays of a fit, and the same
        # arithmetic in numpy (gathers of the coefficients per element) ~1.6x more
        u = np.asarray(u, dtype=float)
        out = np.empty(u.shape + (self.coef.shape[2],))
        _horner(self.coef, self.u0, self.h, u.ravel(), out.reshape(u.size, -1))
        return out

    def nearest_shapes(self, x: np.ndarray) -> np.ndarray:
        i = np.clip(np.rint((np.log(x) - self.u0) / self.h).astype(np.intp), 0, self.shapes.shape[0] - 1)
        return self.shapes[i]


@njit(cache=True, nogil=True)
def _horner(c: np.ndarray, u0: float, h: float, u: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    n = c.shape[1]
    for r in range(u.size):
        s = (u[r] - u0) / h
        i = min(max(int(np.floor(s)), 0), n - 1)
        t = (s - i) * h
        for k in range(c.shape[2]):
            out[r, k] = ((c[0, i, k] * t + c[1, i, k]) * t + c[2, i, k]) * t + c[3, i, k]


def _eig(K: np.ndarray, M: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Lowest n eigenpairs of stacked pencils: (N, n) omega^2, (N, dof, n) M-normalised shapes."""
    L = np.linalg.cholesky(M)
    Li = np.linalg.inv(L)
    A = Li @ K @ np.swapaxes(Li, -1, -2)
    w2, y = np.linalg.eigh(0.5 * (A + np.swapaxes(A, -1, -2)))
    return w2[..., :n], np.swapaxes(Li, -1, -2) @ y[..., :n]


class Surrogate:
    """Frequencies of the calibrated model when groups change per window (see module docstring)."""

    def __init__(self, groups: GroupModel, model_index: list[int] | np.ndarray, n_extra: int = 4):
        self.groups = groups
        self.model_index = np.asarray(model_index, dtype=int)
        self.n_modes = int(min(self.model_index.max() + 1 + n_extra, groups.K.shape[0]))
        w2, phi = _eig(groups.K[None], groups.M[None], self.n_modes)
        self.w2_base = w2[0]
        self.phi_base = phi[0]  # (dof, n_modes)
        self.log_f_base = 0.5 * np.log(np.clip(self.w2_base[self.model_index], 1e-300, None)) - np.log(2 * np.pi)
        self._tables: dict[str, _Table] = {}
        self._nodes: dict[str, dict[int, tuple[np.ndarray, np.ndarray]]] = {}
        self._ritz: dict[tuple[str, ...], tuple] = {}

    # -- sensitivities ---------------------------------------------------------------------------
    def sensitivities(self) -> dict[str, np.ndarray]:
        """d ln f / d x at x = 1 per group, (K,) for the tracked modes (exact eigen-derivative)."""
        phi = self.phi_base[:, self.model_index]
        w2 = self.w2_base[self.model_index]
        out = {}
        for name, g in self.groups.groups.items():
            dk = np.einsum("ik,ij,jk->k", phi, g.dK, phi)
            dm = np.einsum("ik,ij,jk->k", phi, g.dM, phi)
            out[name] = 0.5 * (dk / w2 - dm)
        return out

    # -- exact -----------------------------------------------------------------------------------
    def exact(self, factors: dict[str, np.ndarray]) -> np.ndarray:
        """ln f (N, K) by the full eigen-solution for factors {group: (N,)}. Modes are identified by
        MAC with the baseline's paired modes, or - one group, tabulated - with the followed modes at
        the nearest table node (so both sides name the same physical mode when frequencies cross)."""
        K, M = self.groups.matrices(factors)
        w2, phi = _eig(K, M, self.n_modes)
        if len(factors) == 1 and next(iter(factors)) in self._tables:
            (g, x), = factors.items()
            refs = self._tables[g].nearest_shapes(np.asarray(x, dtype=float))
            idx = np.concatenate([self._follow(phi[i:i + 1], refs[i]) for i in range(len(x))])
        else:
            idx = self._follow(phi, self.phi_base[:, self.model_index])
        w2k = np.take_along_axis(w2, idx, axis=1)
        return 0.5 * np.log(np.clip(w2k, 1e-300, None)) - np.log(2 * np.pi)

    def _follow(self, phi: np.ndarray, ref: np.ndarray) -> np.ndarray:
        """For each reference mode (columns of ``ref``), the index of the mode of ``phi`` (N, dof, n)
        with the largest mass-weighted MAC, one-to-one greedily (largest MAC first)."""
        Mr = self.groups.M @ ref
        c = np.einsum("nda,db->nab", phi, Mr) ** 2  # (N, n, K): unit-normalised shapes in the base M norm
        na = np.einsum("nda,de,nea->na", phi, self.groups.M, phi)
        nb = np.einsum("da,da->a", ref, Mr)
        mac = c / (na[:, :, None] * nb[None, None, :])
        N, n, k = mac.shape
        out = np.zeros((N, k), dtype=int)
        rows = np.arange(N)
        for _ in range(k):
            flat = np.argmax(mac.reshape(N, -1), axis=1)
            i, j = np.divmod(flat, k)
            out[rows, j] = i
            mac[rows, i, :] = -1.0
            mac[rows, :, j] = -1.0
        return out

    # -- one group: interpolation in the factor ---------------------------------------------------
    def _table(self, group: str, lo: float, hi: float) -> _Table:
        t = self._tables.get(group)
        if t is not None and t.lo <= lo and t.hi >= hi:
            return t
        if t is not None:
            lo, hi = min(lo, t.lo), max(hi, t.hi)
        lo = max(min(lo, 1.0) / 1.05, X_FLOOR)
        hi = min(max(hi, 1.0) * 1.05, X_CEIL)
        h = H_NODE
        k = np.arange(np.floor(np.log(lo) / h), np.ceil(np.log(hi) / h) + 1).astype(int)
        u = h * k
        x = np.exp(u)
        w2, phi = self._node_modes(group, k, x)
        i0 = int(np.argmin(np.abs(u)))
        ref = self.phi_base[:, self.model_index]
        logf = np.zeros((len(u), len(self.model_index)))
        shapes = np.zeros((len(u), phi.shape[1], len(self.model_index)))
        for order in (range(i0, len(u)), range(i0, -1, -1)):  # follow outwards from the baseline
            prev = ref
            for i in order:
                j = self._follow(phi[i:i + 1], prev)[0]
                logf[i] = 0.5 * np.log(np.clip(w2[i, j], 1e-300, None)) - np.log(2 * np.pi)
                prev = shapes[i] = phi[i][:, j]
        t = _Table(float(x[0]), float(x[-1]), float(u[0]), float(h), CubicSpline(u, logf, axis=0).c, shapes)
        self._tables[group] = t
        return t

    def _node_modes(self, group: str, k: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The exact eigen-solutions at the nodes ``k`` (x = exp(k H_NODE)), each solved once per group."""
        known = self._nodes.setdefault(group, {})
        new = [i for i, kk in enumerate(k) if int(kk) not in known]
        for a in range(0, len(new), 128):  # in batches: (N, dof, dof) pencils
            part = new[a:a + 128]
            K, M = self.groups.matrices({group: x[part]})
            w2, phi = _eig(K, M, self.n_modes)
            known.update({int(k[i]): (w2[j], phi[j]) for j, i in enumerate(part)})
        return (np.stack([known[int(kk)][0] for kk in k]), np.stack([known[int(kk)][1] for kk in k]))

    # -- several groups: reduced Ritz basis -------------------------------------------------------
    def _ritz_basis(self, names: tuple[str, ...]) -> tuple:
        if names in self._ritz:
            return self._ritz[names]
        gm = self.groups
        phi = self.phi_base
        cols = [phi]
        for g in names:
            grp = gm.groups[g]
            cols.append(np.linalg.solve(gm.K, grp.dK @ phi))
            cols.append(np.linalg.solve(gm.K, grp.dM @ phi * self.w2_base[None]))
        V = np.hstack(cols)
        # M-orthonormal basis of the span (drop directions below 1e-10 of the largest)
        G = V.T @ gm.M @ V
        s, U = np.linalg.eigh(0.5 * (G + G.T))
        keep = s > 1e-10 * s.max()
        T = V @ (U[:, keep] / np.sqrt(s[keep]))
        red = (T.T @ gm.K @ T, T.T @ gm.M @ T,
               {g: (T.T @ gm.groups[g].dK @ T, T.T @ gm.groups[g].dM @ T) for g in names}, T)
        self._ritz[names] = red
        return red

    def _ritz_logf(self, factors: dict[str, np.ndarray]) -> np.ndarray:
        names = tuple(sorted(factors))
        Kr, Mr, d, T = self._ritz_basis(names)
        N = len(next(iter(factors.values())))
        K = np.broadcast_to(Kr, (N, *Kr.shape)).copy()
        M = np.broadcast_to(Mr, (N, *Mr.shape)).copy()
        for g in names:
            dx = (np.asarray(factors[g], dtype=float) - 1.0)[:, None, None]
            K += dx * d[g][0]
            M += dx * d[g][1]
        w2, y = _eig(K, M, min(self.n_modes, Kr.shape[0]))
        # follow in the reduced coordinates: reference = the baseline paired modes projected
        ref = np.linalg.lstsq(T, self.phi_base[:, self.model_index], rcond=None)[0]
        Mref = Mr @ ref
        mac = np.einsum("nra,rb->nab", y, Mref) ** 2
        idx = np.argmax(mac, axis=1)  # (N, K)
        w2k = np.take_along_axis(w2, idx, axis=1)
        return 0.5 * np.log(np.clip(w2k, 1e-300, None)) - np.log(2 * np.pi)

    # -- the call the likelihood makes -------------------------------------------------------------
    def log_frequencies(self, mod: Modification) -> np.ndarray:
        """ln f (B, W, K) of the tracked modes under ``mod`` (factors (B, W) per group)."""
        varying = {g: np.clip(np.asarray(x, dtype=float), X_FLOOR, X_CEIL) for g, x in mod.groups.items()}
        if not varying:
            raise ValueError("a modification without groups has no frequencies to change")
        shape = next(iter(varying.values())).shape
        if len(varying) == 1:
            (g, x), = varying.items()
            t = self._table(g, float(x.min()), float(x.max()))
            return t(np.log(x))
        flat = {g: x.reshape(-1) for g, x in varying.items()}
        # several groups: one small eigenproblem per distinct combination of factors (steps and
        # intermittent effects take few distinct values over the windows)
        stacked = np.column_stack([flat[g] for g in sorted(flat)])
        uniq, inverse = np.unique(stacked, axis=0, return_inverse=True)
        if len(uniq) < len(stacked):
            lf = self._ritz_logf({g: uniq[:, i] for i, g in enumerate(sorted(flat))})
            return lf[np.ravel(inverse)].reshape(*shape, -1)
        return self._ritz_logf(flat).reshape(*shape, -1)

    def delta(self, mod: Modification) -> np.ndarray:
        """ln f - ln f_baseline (B, W, K)."""
        return self.log_frequencies(mod) - self.log_f_base

    def check(self, mod: Modification, n_check: int = 64, seed: int = 0) -> float:
        """Largest relative frequency error of the surrogate against the exact eigen-solution at
        ``n_check`` (batch, window) entries of ``mod`` drawn at random (plus the extremes)."""
        rng = np.random.default_rng(seed)
        first = next(iter(mod.groups.values()))
        B, W = first.shape
        flat = rng.choice(B * W, size=min(n_check, B * W), replace=False)
        for x in mod.groups.values():  # the extremes of every group
            flat = np.concatenate([flat, [int(np.argmin(x)), int(np.argmax(x))]])
        b, w = np.divmod(flat, W)
        sub = Modification({g: x[b, w][None] for g, x in mod.groups.items()})
        approx = self.log_frequencies(sub)[0]
        exact = self.exact({g: x[b, w] for g, x in mod.groups.items()})
        return float(np.max(np.abs(np.expm1(approx - exact))))
