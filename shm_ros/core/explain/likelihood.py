"""The misfit of a candidate: log-frequency residuals with model-form errors and noise integrated out.

Per tracked mode k and (training) window w, with ``r_wk = ln f_obs - ln f_baseline`` and the
candidate's change ``D_wk(theta) = ln f_model(theta) - ln f_baseline`` (:mod:`.surrogate`)::

    r_wk = delta_k + (1 + eta_k) D_wk(theta) + eps_wk

* ``delta_k``: the mode's model-form offset, the same in every window. It splits the likelihood into
  a within-mode part (residuals about the mode's mean, free of delta_k) and a mean part.
  **Within**: delta_k has a flat prior (it is the same in every model compared, so its constant
  cancels in a Bayes factor). **Mean**: the mode means ``ybar_k`` ~ N(0, s^2) with s shared by the
  modes, log-uniform on [0.01 %, 20 %] and integrated on a grid; the nominal parameters stay at the
  baseline MAP but their linearised re-calibration is integrated out of the mean part (flat prior on
  the directions of their sensitivities), so a candidate whose average shifts all modes like the
  nominal stiffness does is not penalised for it.
* ``eta_k`` ~ N(0, tau_k^2): the analysis model's sensitivity of mode k to the effect is itself off by
  a model-form error; integrated out (Laplace, exact in eta given sigma), with eta held within
  3 tau_k. The error of a mode's change is ``tau`` (10 % by default) of the larger of that change
  and the typical mode's (RMS over the modes): tau_k = tau max(1, u / u_k). A mode that barely feels
  the effect in the analysis model may feel it several times more in the structure (a local
  stiffness change and a mode whose curvature in that span the model puts elsewhere), so its error
  is not a fraction of its own tiny change; without this, such a mode, precise over hundreds of
  windows, pulls the effect's size far off (a span's knee 30 % too steep).
* ``eps_wk`` ~ N(0, sigma_k^2): identification scatter, sigma_k^2 inverse-gamma (shape a, mode
  ``noise_guess^2``) and integrated out in closed form: ``-(a + m/2) ln(b + SSW/2)``.
  On dense records (a ``timing``) the misfit also drifts: a random walk under the scatter, its
  ratio to the scatter integrated on a grid (:mod:`.drift`); the sums of squares are then those of
  the mode's differences between successive windows in the metric of their covariance.

Damping (a candidate with ``Modification.damping``) enters the same way on ``ln zeta``, within part
only (no model baseline for damping). All functions are batched over parameter vectors (B, ...).

:func:`catch_all_gain` is the flexible alternative against which named candidates are measured: per
mode a linear model in a basis of smooth functions of the covariates and of time (temperature hinges,
time trend and steps, amplitude), with Zellner's g-prior (g = n) and the same inverse-gamma noise,
so its Bayes factor over the nominal model is closed form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from shm_ros.core.logexp import log_mean_exp

from .drift import ModeDrift, Timing

S_RANGE = (1e-4, 0.2)  # model-form offset scale, relative frequency, log-uniform
N_S = 41
ETA_MAX = 3.0  # |eta| <= 3 tau


def _eta_marginal(S0: np.ndarray, A: np.ndarray, c: np.ndarray, alpha: np.ndarray, b: float,
                  tau: np.ndarray) -> np.ndarray:
    """Log marginal of residuals minus (1 + eta) d with eta ~ N(0, tau^2) and the inverse-gamma noise:
    ``S0`` the residual's sum of squares after d, ``A`` d's, ``c`` their cross sum (batched)."""
    sig2 = (b + 0.5 * S0) / (alpha + 1.0)
    eta = np.zeros_like(S0)
    ssw = S0
    for _ in range(3):  # eta given sigma^2, sigma^2 given eta (converges in a few steps)
        prec = A / sig2 + 1.0 / tau ** 2
        # at most 3 tau: with thousands of windows a free eta could even flip the effect's sign
        eta = np.clip((c / sig2) / prec, -ETA_MAX * tau, ETA_MAX * tau)
        ssw = np.maximum(S0 - 2.0 * eta * c + eta ** 2 * A, 0.0)
        sig2 = (b + 0.5 * ssw) / (alpha + 1.0)
    prec = A / sig2 + 1.0 / tau ** 2
    return -alpha * np.log(b + 0.5 * ssw) - 0.5 * eta ** 2 / tau ** 2 - 0.5 * np.log(tau ** 2 * prec)


def _spread(tau: float, u2: np.ndarray) -> np.ndarray:
    """tau_k = tau max(1, u / u_k) from the changes' mean squares u2 (B, K) (module docstring)."""
    return tau * np.sqrt(np.maximum(1.0, np.mean(u2, axis=1, keepdims=True) / np.maximum(u2, 1e-300)))


@dataclass
class _Part:
    """Centered residuals of one quantity (frequencies or damping) on the training windows; with a
    ``timing`` each mode's misfit is a random-walk drift plus scatter, the drift integrated
    (:mod:`.drift`)."""

    r: np.ndarray  # (W, K) residuals, 0 where missing
    ok: np.ndarray  # (W, K) bool
    n: np.ndarray  # (K,) windows per mode
    a: float
    b: float
    drifts: list[_Drift] = field(default_factory=list)

    @classmethod
    def make(cls, r: np.ndarray, a: float, guess: float, timing: Timing | None = None) -> _Part:
        ok = np.isfinite(r)
        n = ok.sum(axis=0)
        rr = np.where(ok, r, 0.0)
        mean = rr.sum(axis=0) / np.maximum(n, 1)
        rc = np.where(ok, rr - mean, 0.0)
        part = cls(rc, ok, n, a, a * guess ** 2)
        if timing is not None:
            part.drifts = _Drift.groups(rc, ok, timing)
        return part

    def center(self, d: np.ndarray) -> np.ndarray:
        """d (B, W, K) centered per mode over the windows where the mode was seen."""
        d = np.where(self.ok, d, 0.0)
        return np.where(self.ok, d - d.sum(axis=1, keepdims=True) / np.maximum(self.n, 1), 0.0)

    def loglik(self, d: np.ndarray | None, tau: float, spread: bool = False) -> np.ndarray:
        """Within-mode log marginal (B, K) of residuals minus (1 + eta) d, eta ~ N(0, tau_k^2).

        ``spread``: tau_k = tau max(1, u / u_k), u_k the RMS of mode k's change over the windows and
        u its RMS over the modes (module docstring); else tau_k = tau."""
        m = np.maximum(self.n - 1, 0)
        alpha = self.a + 0.5 * m
        s0 = np.sum(self.r ** 2, axis=0)
        if d is None:
            out = (-alpha * np.log(self.b + 0.5 * s0))[None]
            for g in self.drifts:
                out[0, g.modes] = g.null(alpha, self.b)
            return out
        if sum(g.modes.size for g in self.drifts) == self.r.shape[1]:  # every mode drifts: A for the taus only
            dm = np.where(self.ok, d, 0.0)
            A = np.einsum("bwk,bwk->bk", dm, dm) - dm.sum(axis=1) ** 2 / np.maximum(self.n, 1)
            out = np.zeros_like(A)
        else:
            dc = self.center(d)
            e = self.r[None] - dc
            A = np.sum(dc ** 2, axis=1)
            out = None
        taus = _spread(tau, A / np.maximum(self.n, 1)) if spread else np.full_like(A, tau)
        if out is None:
            out = _eta_marginal(np.sum(e ** 2, axis=1), A, np.sum(dc * e, axis=1), alpha, self.b, taus)
        for g in self.drifts:
            out[:, g.modes] = g.loglik(d, alpha, self.b, taus)
        return out

    def sigma(self) -> np.ndarray:
        return np.sqrt(np.sum(self.r ** 2, axis=0) / np.maximum(self.n - 1, 1))


@dataclass
class _Drift:
    """Modes seen in the same windows, their misfit as drift plus scatter (:mod:`.drift`): the
    residuals' differences and, per ratio on the grid, their quadratic form."""

    modes: np.ndarray  # (G,) mode indices
    mode: ModeDrift
    dr: np.ndarray  # (m, G) differences of the residuals
    syy: np.ndarray  # (n_lam, G) dr' T^-1 dr
    prepared: tuple[np.ndarray, np.ndarray, np.ndarray]  # ModeDrift.prepare(dr)

    @classmethod
    def groups(cls, r: np.ndarray, ok: np.ndarray, timing: Timing) -> list[_Drift]:
        out = []
        patterns: dict[bytes, list[int]] = {}
        for k in range(r.shape[1]):
            patterns.setdefault(ok[:, k].tobytes(), []).append(k)
        for ks in patterns.values():
            mode = ModeDrift.make(ok[:, ks[0]], timing)
            if mode is None:
                continue
            dr = mode.diff(r[:, ks].T).T  # (m, G)
            syy = np.stack([np.sum(dr * mode.solve(i, dr), axis=0) for i in range(len(timing.lam))])
            out.append(cls(np.array(ks), mode, dr, syy, mode.prepare(dr)))
        return out

    def null(self, alpha: np.ndarray, b: float) -> np.ndarray:
        """(G,) log marginal of the nominal model."""
        return log_mean_exp(self._null_grid(alpha, b), axis=0)

    def _null_grid(self, alpha: np.ndarray, b: float) -> np.ndarray:
        return -alpha[self.modes] * np.log(b + 0.5 * self.syy) - 0.5 * self.mode.logdets[:, None]

    def evidence(self, alpha: np.ndarray, b: float) -> tuple[np.ndarray, np.ndarray]:
        """Per mode of the group, the log Bayes factor of a drift (the grid's ratios above 0) over
        none in the nominal misfit, and the ratio's posterior mean."""
        ll = self._null_grid(alpha, b)  # (n_lam, G)
        lam = np.asarray(self.mode.lam)[:, None]
        post = np.exp(ll - ll.max(axis=0, keepdims=True))
        post /= post.sum(axis=0, keepdims=True)
        return log_mean_exp(ll[1:], axis=0) - ll[0], np.sum(post * lam, axis=0)

    def loglik(self, d: np.ndarray, alpha: np.ndarray, b: float, tau: np.ndarray) -> np.ndarray:
        """(B, G) for changes d (B, W, K)."""
        if self.mode.idx.size < d.shape[1]:
            d = d[:, self.mode.idx]
        if self.modes.size < d.shape[2]:
            d = d[:, :, self.modes]
        A, cy = self.mode.forms(np.diff(d, axis=1), self.prepared)  # (n_lam, B, G)
        S0 = np.maximum(self.syy[:, None, :] - 2.0 * cy + A, 0.0)
        ll = _eta_marginal(S0, A, cy - A, alpha[self.modes], b, tau[:, self.modes])
        return log_mean_exp(ll - 0.5 * self.mode.logdets[:, None, None], axis=0)


class CandidateLikelihood:
    """log p(data | candidate change) - log p(data | nominal), batched (see module docstring).

    ``r`` (W, K): baseline log-frequency residuals of the training windows (NaN = missing);
    ``nominal_sens`` (K, p): d ln f / d ln theta of the nominal parameters (the mean part's free
    directions); ``rd`` (W, K): log damping ratios, or None.
    """

    def __init__(self, r: np.ndarray, nominal_sens: np.ndarray | None = None, rd: np.ndarray | None = None,
                 tau: float = 0.1, noise_guess: float = 0.003, damping_noise_guess: float = 0.2,
                 ig_shape: float = 1.0, timing: Timing | None = None):
        self.tau = float(tau)
        self.noise_guess = float(noise_guess)
        self.freq = _Part.make(r, ig_shape, noise_guess, timing)
        self.damp = (None if rd is None or not np.isfinite(rd).any()
                     else _Part.make(rd, ig_shape, damping_noise_guess, timing))
        ok = self.freq.ok
        rr = np.where(ok, r, 0.0)
        self.ybar = rr.sum(axis=0) / np.maximum(self.freq.n, 1)
        K = r.shape[1]
        J = np.zeros((K, 0)) if nominal_sens is None else np.asarray(nominal_sens, dtype=float).reshape(K, -1)
        if J.shape[1]:
            q, sv, _ = np.linalg.svd(J, full_matrices=False)
            q = q[:, sv > 1e-6 * sv.max()]
        else:
            q = np.zeros((K, 0))
        self.P = np.eye(K) - q @ q.T  # removes what a re-calibration of the nominal parameters absorbs
        self.dof = K - q.shape[1]
        self.s_grid = np.exp(np.linspace(np.log(S_RANGE[0]), np.log(S_RANGE[1]), N_S))
        sig = self.freq.sigma()
        self.mean_var = float(np.mean(sig ** 2 / np.maximum(self.freq.n, 1)))
        self._null = float(self._total(None, None)[0])

    def drift(self) -> dict[int, tuple[float, float]]:
        """Mode index -> (log Bayes factor of a drift over none in the nominal frequency misfit, the
        drift-to-scatter ratio's posterior mean); empty when the misfit is independent."""
        part = self.freq
        alpha = part.a + 0.5 * np.maximum(part.n - 1, 0)
        out: dict[int, tuple[float, float]] = {}
        for g in part.drifts:
            bf, lam = g.evidence(alpha, part.b)
            out.update({int(k): (float(x), float(y)) for k, x, y in zip(g.modes, bf, lam, strict=True)})
        return out

    def _mean_part(self, dbar: np.ndarray | None) -> np.ndarray:
        y = self.ybar[None] if dbar is None else self.ybar[None] - dbar
        e = y @ self.P
        q = np.sum(e ** 2, axis=1)  # (B,)
        v = self.s_grid ** 2 + self.mean_var
        ll = -0.5 * self.dof * np.log(2 * math.pi * v)[None] - 0.5 * q[:, None] / v[None]
        return log_mean_exp(ll, axis=1)

    def _total(self, d: np.ndarray | None, dd: np.ndarray | None) -> np.ndarray:
        out = self.freq.loglik(d, self.tau, spread=True).sum(axis=1)
        dbar = None
        if d is not None:
            dm = np.where(self.freq.ok, d, 0.0)
            dbar = dm.sum(axis=1) / np.maximum(self.freq.n, 1)
        out = out + self._mean_part(dbar)
        if self.damp is not None and dd is not None:
            out = out + self.damp.loglik(dd, self.tau).sum(axis=1) - self.damp.loglik(None, self.tau).sum(axis=1)
        return out

    def gain(self, d: np.ndarray | None, dd: np.ndarray | None = None) -> np.ndarray:
        """Log-likelihood gain (B,) of log-frequency changes ``d`` (B, W, K) and log-damping changes
        ``dd`` (B, W, K or 1) over the nominal model."""
        if d is None:
            d = np.zeros((1 if dd is None else dd.shape[0], *self.freq.r.shape))
        if dd is not None:
            dd = np.broadcast_to(dd, (dd.shape[0], *self.freq.r.shape))
        return self._total(d, dd) - self._null


def _g_prior_loglik(y: np.ndarray, X: np.ndarray, a: float, b: float) -> tuple[float, float, np.ndarray | None]:
    """Log marginals (nominal, g-prior model) of ``y`` on ``X`` (both free of the offset; g = number of
    values) with the inverse-gamma noise of shape ``a`` after the data (constants shared by both left
    out), and the model's fitted values."""
    s0 = float(y @ y)
    null = -a * math.log(b + 0.5 * s0)
    X = X[:, np.linalg.norm(X, axis=0) > 1e-12]
    if X.shape[1] == 0:
        return null, null, None
    q, sv, _ = np.linalg.svd(X, full_matrices=False)
    q = q[:, sv > 1e-8 * sv.max()]
    g = float(y.size)
    proj = q @ (q.T @ y)
    sg = s0 - g / (1 + g) * float(y @ proj)
    return null, -0.5 * q.shape[1] * math.log1p(g) - a * math.log(b + 0.5 * sg), g / (1 + g) * proj


def catch_all_gain(r: np.ndarray, basis: np.ndarray, noise_guess: float = 0.003, ig_shape: float = 1.0,
                   timing: Timing | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-mode log Bayes factor (K,) of a g-prior linear model in ``basis`` (W, p) over the nominal
    model, and the fitted values (W, K). Missing residuals (NaN) are left out mode by mode. With a
    ``timing`` the misfit is drift plus scatter (:mod:`.drift`): both models are fitted to the
    whitened differences and each integrates the drift ratio over the grid."""
    W, K = r.shape
    gains = np.zeros(K)
    fitted = np.full((W, K), np.nan)
    b = ig_shape * noise_guess ** 2
    for k in range(K):
        ok = np.isfinite(r[:, k])
        n = int(ok.sum())
        if n < 5:
            continue
        y = r[ok, k] - r[ok, k].mean()
        null, alt, fit = _g_prior_loglik(y, basis[ok] - basis[ok].mean(axis=0), ig_shape + 0.5 * (n - 1), b)
        if fit is None:
            continue
        gains[k] = alt - null
        fitted[ok, k] = fit
        mode = None if timing is None else ModeDrift.make(ok, timing)
        if mode is None:
            continue
        dy, dX = mode.diff(np.where(ok, r[:, k], 0.0)), mode.diff(basis.T).T
        lls = np.array([_g_prior_loglik(mode.whiten(i, dy), mode.whiten(i, dX), ig_shape + 0.5 * (n - 1), b)[:2]
                        for i in range(len(mode.lam))]) - 0.5 * mode.logdets[:, None]
        gains[k] = float(log_mean_exp(lls[:, 1]) - log_mean_exp(lls[:, 0]))
    return gains, fitted
