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

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_solve_banded, cholesky_banded, solve_banded

LAM_GRID = (0.0, 1e-3, 3e-3, 0.01, 0.03, 0.1, 0.3, 1.0)
MIN_WINDOWS = 40  # fewer windows: independent misfit (as explain.SPARSE_WINDOWS)


def log_mean_exp(a: np.ndarray, axis: int = 0) -> np.ndarray:
    """ln of the mean of exp(a) along ``axis`` (the grid prior's average)."""
    mx = np.max(a, axis=axis, keepdims=True)
    mx = np.where(np.isfinite(mx), mx, 0.0)
    return np.log(np.mean(np.exp(a - mx), axis=axis)) + np.squeeze(mx, axis=axis)


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
    """One mode's differences and, per ratio on the grid, the banded Cholesky factor of T and log|T|."""

    idx: np.ndarray  # windows where the mode was seen
    factors: list[np.ndarray]
    logdets: np.ndarray

    @classmethod
    def make(cls, ok: np.ndarray, timing: Timing) -> ModeDrift | None:
        idx = np.flatnonzero(ok)
        if idx.size < 4:
            return None
        gaps = np.diff(timing.steps[idx])
        factors, logdets = [], []
        for lam in timing.lam:
            ab = np.zeros((2, idx.size - 1))
            ab[0] = 2.0 + lam * gaps
            ab[1, :-1] = -1.0
            c = cholesky_banded(ab, lower=True)
            factors.append(c)
            logdets.append(2.0 * np.sum(np.log(c[0])))
        return cls(idx, factors, np.array(logdets))

    def forms(self, x: np.ndarray, zr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per ratio on the grid, ``|L^-1 x|^2`` and ``(L^-1 x) . zr`` over the differences (T = L L^T),
        by forward substitution on the bidiagonal factor, every ratio and column at once:
        ``x`` (n - 1, *cols), ``zr`` (n_lam, n - 1, *cols or broadcastable) -> two (n_lam, *cols)."""
        ext = (slice(None),) + (None,) * (x.ndim - 1)
        inv = 1.0 / np.array([f[0] for f in self.factors])  # (n_lam, n - 1)
        sub = np.array([f[1] for f in self.factors])
        z = x[0][None] * inv[:, 0][ext]
        a, c = z * z, z * zr[:, 0]
        for j in range(1, x.shape[0]):
            z = (x[j][None] - sub[:, j - 1][ext] * z) * inv[:, j][ext]
            a += z * z
            c += z * zr[:, j]
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
