"""Misfit correlated from window to window: a slow random-walk drift under the scatter, integrated out.

A slow driver nobody measured (moisture, a drifting sensor, a temperature the air sensor does not
follow) leaves a misfit that wanders from window to window; with independent errors the likelihood
reads every wander as signal, and a step or an added mass fits it with tens of nats. Here each mode's
misfit is a random walk ``s`` plus the independent scatter ``eps`` of the identification::

    x_j = s_j + eps_j,   s_(j+1) - s_j ~ N(0, lam g_j sigma^2),   eps_j ~ N(0, sigma^2)

with ``g_j`` the time between the mode's windows j and j + 1 in typical spacings (a held-out block or
a missing window is a longer step of the walk). The walk's start is free (a flat prior, like the
independent model's per-mode offset), so the likelihood is that of the differences ``x_(j+1) - x_j``,
whose covariance ``sigma^2 T(lam)`` is tridiagonal: ``lam g_j + 2`` on the diagonal, ``-1`` beside it.
``lam = 0`` is the independent model exactly (the differences' quadratic form is the centered sum of
squares); the drift-to-scatter ratio ``lam`` has a uniform prior on a grid (:data:`LAM_GRID`) and is
integrated out per mode, in every model compared, the nominal one too. An AR(1) driver with a
coefficient of 0.9-0.995 over a few hundred windows is such a walk to within the grid's resolution.

A sudden change is one large step of the walk, which the Gaussian steps make costly, so a step the
data hold is still named; a wander is many steps of the walk's size, which the walk explains.

With few windows (sparse event records) no ratio can be estimated: :func:`Timing.of` gives None and
the misfit is independent.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.fft import dst
from scipy.linalg import cho_solve_banded, cholesky_banded, solve_banded

LAM_GRID = (0.0, 1e-3, 3e-3, 0.01, 0.03, 0.1, 0.3, 1.0)
MIN_WINDOWS = 40  # fewer windows: independent misfit (as explain.SPARSE_WINDOWS)
MAX_LONG_STEPS = 32  # more longer steps (and more than a tenth of the steps): banded solves instead


@dataclass(frozen=True)
class Timing:
    """The windows' times in typical spacings (median interval = 1) and the ratio grid."""

    steps: np.ndarray  # (W,)
    lam: tuple[float, ...] = LAM_GRID

    @classmethod
    def of(cls, times_s: np.ndarray | None, min_windows: int = MIN_WINDOWS) -> Timing | None:
        """None without times, with fewer than ``min_windows`` windows or times not in order."""
        if times_s is None:
            return None
        t = np.asarray(times_s, dtype=float)
        if t.size < min_windows or not np.all(np.isfinite(t)):
            return None
        dt = np.diff(t)
        if np.any(dt <= 0):
            return None
        return cls(steps=(t - t[0]) / float(np.median(dt)))


@dataclass
class ModeDrift:
    """One mode's differences and, per ratio on the grid, the banded Cholesky factor of T and log|T|.

    The quadratic forms of a batch (:meth:`forms`) use the spectrum of T's regular part: with unit
    steps T(lam) = D + lam I, D the second-difference matrix (2 on the diagonal, -1 beside it), whose
    eigenvectors are the discrete sine transform's (eigenvalues ``2 - 2 cos(pi k / (m + 1))``); the
    longer steps (held-out blocks, missing windows) are a correction of rank p at their rows
    (Woodbury). One transform serves every ratio on the grid."""

    idx: np.ndarray  # windows where the mode was seen
    factors: list[np.ndarray]
    logdets: np.ndarray
    lam: tuple[float, ...] = LAM_GRID
    w: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # (m, n_lam) 1 / (eigenvalue of D + lam)
    # (n_lam, p, m) the sine vectors at the longer steps, weighted by w
    rw: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 0)))
    kinv: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 0)))  # (n_lam, p, p) Woodbury inverses

    @classmethod
    def make(cls, ok: np.ndarray, timing: Timing) -> ModeDrift | None:
        idx = np.flatnonzero(ok)
        if idx.size < 4:
            return None
        gaps = np.diff(timing.steps[idx])
        m = gaps.size
        factors, logdets = [], []
        for lam in timing.lam:
            ab = np.zeros((2, m))
            ab[0] = 2.0 + lam * gaps
            ab[1, :-1] = -1.0
            c = cholesky_banded(ab, lower=True)
            factors.append(c)
            logdets.append(2.0 * np.sum(np.log(c[0])))
        k = np.arange(1, m + 1)
        mu = 2.0 - 2.0 * np.cos(np.pi * k / (m + 1))
        long = np.flatnonzero(np.abs(gaps - 1.0) > 1e-9)
        rows = np.sqrt(2.0 / (m + 1)) * np.sin(np.pi * np.outer(long + 1, k) / (m + 1))
        lams = np.asarray(timing.lam)
        w = 1.0 / (mu[:, None] + lams[None, :])  # (m, n_lam)
        rw = rows[None] * w.T[:, None, :]  # (n_lam, p, m)
        kinv = np.zeros((lams.size, long.size, long.size))
        for i, lam in enumerate(lams):
            if lam > 0.0 and long.size:
                kinv[i] = np.linalg.inv(np.diag(1.0 / (lam * (gaps[long] - 1.0))) + rw[i] @ rows.T)
        return cls(idx, factors, np.array(logdets), tuple(timing.lam), w, rw, kinv)

    def prepare(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What :meth:`forms` needs of the fixed right-hand side ``y`` (m, G), computed once."""
        yh = dst(y, type=1, norm="ortho", axis=0)  # (m, G)
        return yh.T, self.rw @ yh, y  # (G, m), (n_lam, p, G), (m, G)

    def forms(self, x: np.ndarray, prepared: tuple[np.ndarray, np.ndarray, np.ndarray]
              ) -> tuple[np.ndarray, np.ndarray]:
        """Per ratio on the grid, ``x' T^-1 x`` and ``x' T^-1 y`` over the differences, every ratio and
        column at once: ``x`` (B, m, G), ``prepared`` :meth:`prepare` of y (m, G) -> two (n_lam, B, G).
        The sine transform diagonalises the regular walk; the longer steps' rank-p correction (Woodbury)
        is one matrix product for every ratio (zero at lam = 0)."""
        yh, ay, y = prepared
        B, m, G = x.shape
        if self.rw.shape[1] > max(MAX_LONG_STEPS, m // 10):  # many longer steps: banded solves per ratio
            xt = np.ascontiguousarray(x.transpose(1, 0, 2)).reshape(m, B * G)
            tx = [self.solve(i, xt).reshape(m, B, G) for i in range(len(self.lam))]
            xx = xt.reshape(m, B, G)
            return (np.stack([np.sum(xx * t, axis=0) for t in tx]),
                    np.stack([np.einsum("mbg,mg->bg", t, y) for t in tx]))
        xh = dst(np.ascontiguousarray(x.transpose(0, 2, 1)), type=1, norm="ortho", axis=2, overwrite_x=True)
        a = np.moveaxis(np.square(xh) @ self.w, 2, 0)  # (B, G, m) @ (m, n_lam) -> (n_lam, B, G)
        c = np.moveaxis((xh * yh[None]) @ self.w, 2, 0)
        if self.rw.shape[1]:
            ax = self.rw @ xh.reshape(B * G, m).T  # (n_lam, p, B G)
            kx = self.kinv @ ax
            a -= np.sum(ax * kx, axis=1).reshape(a.shape)
            c -= np.sum(kx.reshape(*kx.shape[:2], B, G) * ay[:, :, None, :], axis=1)
        return a, c

    def diff(self, x: np.ndarray) -> np.ndarray:
        """Differences along the mode's windows; ``x`` (..., W) -> (..., n - 1)."""
        return np.diff(x[..., self.idx], axis=-1)

    def solve(self, i: int, y: np.ndarray) -> np.ndarray:
        """T(lam_i)^-1 y for y (n - 1, ...)."""
        return cho_solve_banded((self.factors[i], True), y)

    def whiten(self, i: int, y: np.ndarray) -> np.ndarray:
        """L^-1 y (T = L L^T) for y (n - 1, ...)."""
        return solve_banded((1, 0), self.factors[i], y)
