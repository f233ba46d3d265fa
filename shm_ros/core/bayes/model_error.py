"""Modal likelihood with a systematic model-error term shared by all windows.

The Gaussian likelihood (:class:`~.likelihoods.GaussianModalLikelihood`) treats every window's
error as independent given theta, so its posterior narrows as 1/sqrt(windows) whatever the model's
own error: with a thousand windows a stiffness factor comes out to a few hundredths of a percent
even when the model cannot reproduce the structure's frequencies to better than a percent. Here,
per tracked mode k and window w (frequencies relative to the mode's mean observed frequency
``f_ref``, as in the Gaussian likelihood)

    f_wk / f_ref_k = f_model_k(theta) / f_ref_k + delta_k + eps_wk,
    delta_k ~ N(0, s^2)        systematic model error of mode k, the same in every window
    eps_wk  ~ N(0, sigma_k^2)  identification scatter and environmental variation of the window

so the windows of mode k are jointly Gaussian with covariance ``sigma_k^2 I + s^2 1 1^T``. Their
likelihood factorises exactly into the within-mode scatter W_k (n_k - 1 degrees of freedom, variance
sigma_k^2, independent of theta) and the mean residual ``ybar_k = mean_w(f_wk / f_ref_k) -
f_model_k / f_ref_k ~ N(0, s^2 + sigma_k^2 / n_eff_k)``: more windows pin the mean residual, but the
model-error variance s^2 stays, so the posterior stops narrowing once s dominates.

* ``n_eff_k`` corrects for windows correlated in time (temperature drifts slowly, so neighbouring
  windows share most of their environmental shift): ``n (1 - rho) / (1 + rho)`` with ``rho`` the
  lag-1 autocorrelation of the mode's frequencies in time order (an AR(1) over window order; ``rho``
  is a property of the data alone, since the residual differs from the frequency by a constant).
* ``sigma_k^2`` has the inverse-gamma prior of the Gaussian likelihood and is integrated out by
  generalised Gauss-Laguerre quadrature over its posterior given W_k (exact for the W_k factor), or
  sampled as a log-variance (``variance="sampled"``).
* ``s`` is one model-error scale shared by the modes (the data hold a single systematic offset per
  mode, so a scale per mode would be informed by one number each and only its prior would show; a
  shared scale is learnt from all modes together). Its prior is log-uniform on [0.01 %, 20 %]
  (:data:`FREQ_SCALE_RANGE`) - scale-invariant ignorance between the resolution of a mean
  identified frequency (a systematic error below 0.01 % cannot be told from none) and an error so
  large the model's modes would no longer pair with the data's. It is integrated out on a log grid.
  The inferred systematic offset of every mode is reported by :meth:`variance_estimates`.
* Shapes, likewise: window w's shape residual orthogonal to the unit model shape u is
  ``r_w = a_w e_k + eps_w`` with ``a_w = u . phi_w``, a shared shape error ``e_k ~ N(0, t^2 I)``
  (t log-uniform on [0.1 %, 30 %], :data:`SHAPE_SCALE_RANGE`) and window scatter
  ``eps_w ~ N(0, tau_k^2 I)``; W (within) and the amplitude-weighted mean residual factorise the
  same way, from the scatter matrices ``S`` and ``S^2`` of the data.

Model modes are paired with the data's modes by :func:`~.likelihoods.paired_predictions`.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import roots_genlaguerre, roots_hermitenorm

from shm_ros.core.logexp import logsumexp
from shm_ros.core.observations import ModalObservations

from .forward import ModalPredictor
from .likelihoods import (
    InverseGamma,
    ModalStatistics,
    ig_marginal_loglik,
    ig_posterior_mean,
    log_variance_initial,
    log_variance_logprior,
    paired_predictions,
    set_pairing,
)

FREQ_SCALE_RANGE = (1e-4, 0.2)  # model-error scale s of the frequencies (relative), log-uniform
SHAPE_SCALE_RANGE = (1e-3, 0.3)  # model-error scale t of a unit shape's components, log-uniform
_LOG2PI = math.log(2.0 * math.pi)


def autocorrelation(values: np.ndarray, lags: int) -> np.ndarray:
    """Sample autocorrelation of a series at lags 1..``lags`` (zeros when the series is shorter than
    ``lags + 1`` values or has no variance)."""
    d = np.asarray(values, dtype=float)
    d = d - d.mean() if d.size else d
    den = float(np.dot(d, d))
    if den <= 0 or d.size <= lags:
        return np.zeros(lags)
    return np.array([float(np.dot(d[h:], d[:-h])) / den for h in range(1, lags + 1)])


def lag1_autocorrelation(values: np.ndarray) -> float:
    """Lag-1 autocorrelation of a series (0 for fewer than 3 values or no variance)."""
    v = np.asarray(values, dtype=float)
    return 0.0 if v.size < 3 else float(autocorrelation(v, 1)[0])


def effective_count(n: float, rho: float) -> float:
    """Windows worth of independent information in the mean of ``n`` AR(1)-correlated windows."""
    r = min(max(rho, 0.0), 0.99)
    return float(min(max(n * (1.0 - r) / (1.0 + r), 1.0), n)) if n > 0 else 0.0


def _scale_grid(lo: float, hi: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes of a log-uniform prior on [lo, hi] and their log weights (midpoints in log s)."""
    edges = np.linspace(math.log(lo), math.log(hi), n + 1)
    return np.exp(0.5 * (edges[1:] + edges[:-1])), np.full(n, -math.log(n))


def _variance_nodes(prior: InverseGamma, dof: np.ndarray, n_quad: int) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature of the IG posterior of a variance with ``dof`` residual values: the posterior is
    ``(b + W/2) / g`` with ``g ~ Gamma(a + dof/2)``; returns the nodes of 1/g (m, Q) and log weights."""
    inv_g = np.empty((dof.size, n_quad))
    logw = np.empty((dof.size, n_quad))
    z, wz = roots_hermitenorm(n_quad)
    for k, nk in enumerate(dof):
        a = prior.shape + 0.5 * float(nk)
        if a <= 30.0:
            x, w = roots_genlaguerre(n_quad, a - 1.0)
        else:  # Laguerre weights overflow; Wilson-Hilferty: (g / a)^(1/3) is nearly normal
            c = 1.0 / (9.0 * a)
            x, w = a * (1.0 - c + z * math.sqrt(c)) ** 3, wz
        inv_g[k] = 1.0 / x
        logw[k] = np.log(np.maximum(w, 1e-300)) - math.log(float(np.sum(w)))
    return inv_g, logw


class ModelErrorLikelihood:
    """Frequencies (and shapes) with a shared systematic model-error term; see the module doc."""

    def __init__(self, predictor: ModalPredictor, obs: ModalObservations, *, use_shapes: bool = True,
                 variance: str = "marginal", freq_prior: InverseGamma | None = None,
                 shape_prior: InverseGamma | None = None, time_correlation: bool = True,
                 freq_scale_range: tuple[float, float] = FREQ_SCALE_RANGE,
                 shape_scale_range: tuple[float, float] = SHAPE_SCALE_RANGE,
                 n_grid: int = 32, n_quad: int = 6, pairing: np.ndarray | None = None, n_theta: int = 0):
        if variance not in ("marginal", "sampled"):
            raise ValueError(f"variance must be 'marginal' or 'sampled', got {variance!r}")
        if use_shapes and obs.has_shapes and list(predictor.sensor_ids) != list(obs.sensor_ids):
            raise ValueError("predictor sensors must be the data's sensors in the same order: "
                             f"{predictor.sensor_ids} vs {obs.sensor_ids}")
        for name, (lo, hi) in (("freq_scale_range", freq_scale_range), ("shape_scale_range", shape_scale_range)):
            if not 0 < lo < hi:
                raise ValueError(f"{name} must be 0 < low < high, got {(lo, hi)}")
        self.predictor = predictor
        self.stats = st = ModalStatistics.from_observations(obs, use_shapes=use_shapes)
        if predictor.n_modes < len(st.f_ref):
            raise ValueError(f"the model offers {predictor.n_modes} modes but the data track {len(st.f_ref)}")
        if pairing is not None:
            set_pairing(self, pairing)
        self.n_theta = n_theta  # structural parameters (0: every column of x is one)
        self.variance = variance
        self.freq_prior = freq_prior or InverseGamma.weak(0.01)
        self.shape_prior = shape_prior or InverseGamma.weak(0.05)
        self.mode_numbers = list(obs.mode_numbers)
        self._init_frequencies(obs, time_correlation, freq_scale_range, n_grid, n_quad)
        self._init_shapes(shape_scale_range, n_grid, n_quad)
        names = [f"sigma2_f_mode{k}" for k in self.mode_numbers]
        if self.uses_shapes:
            names += [f"sigma2_shape_mode{k}" for k in self.mode_numbers]
        self.variance_names = names
        self.extra_names = [f"log_{n}" for n in names] if variance == "sampled" else []

    def _init_frequencies(self, obs: ModalObservations, time_correlation: bool,
                          freq_scale_range: tuple[float, float], n_grid: int, n_quad: int) -> None:
        st, m = self.stats, len(self.mode_numbers)
        # frequencies: within-mode scatter (theta-independent) and the effective count of the mean
        self.xbar = st.s1 / st.n_freq
        self.w_f = np.maximum(st.s2 - st.s1**2 / st.n_freq, 0.0)
        self.dof_f = np.maximum(st.n_freq - 1.0, 0.0)
        order = np.argsort(obs.times, kind="stable")
        rho = np.zeros(m)
        if time_correlation:
            for k in range(m):
                col = obs.frequencies_hz[order, k]
                rho[k] = lag1_autocorrelation(col[np.isfinite(col) & (col > 0)])
        self.rho = rho
        self.n_eff = np.array([effective_count(n, r) for n, r in zip(st.n_freq, rho, strict=True)])
        # the variance posterior is narrow once every mode has 20 windows: 3 nodes integrate the
        # smooth integrand to far below the sampler's noise (checked against 12 in the tests)
        q_f = 3 if np.all(self.dof_f >= 20) else n_quad
        inv_g, self._logw_f = _variance_nodes(self.freq_prior, self.dof_f, q_f)
        self._sigma2_nodes = (self.freq_prior.scale + 0.5 * self.w_f)[:, None] * inv_g  # (m, Q)
        self._c_f = ig_marginal_loglik(self.w_f, self.dof_f, self.freq_prior)  # (m,)
        # Hz instead of relative values, and n^(-1/2) per mode: N(ybar | 0, s^2 + sigma^2/n) is the
        # density of the mean, the windows' joint density has the sum's (sqrt(n) wider)
        self.log_jacobian = -float(np.sum(st.n_freq * np.log(st.f_ref))) - 0.5 * float(np.sum(np.log(st.n_freq)))
        self.s_grid, self._s_logprior = _scale_grid(*freq_scale_range, n_grid)
        # the variance nodes of the marginal do not depend on theta: their Gaussian's log
        # normalisation (with the node weights) and 1/(2v) once, (Q, 1, G, m) as _mixture lays out
        v = self.s_grid[:, None] ** 2 + (self._sigma2_nodes / self.n_eff[:, None]).T[:, None, None]
        self._freq_const = -0.5 * (_LOG2PI + np.log(v)) + self._logw_f.T[:, None, None]
        self._freq_half_inv = 0.5 / v

    def _init_shapes(self, shape_scale_range: tuple[float, float], n_grid: int, n_quad: int) -> None:
        st = self.stats
        # shapes: scatter matrices and their squares (the amplitude-weighted mean residual)
        self.uses_shapes = st.uses_shapes
        self.n_sensors = st.n_sensors
        d = max(self.n_sensors - 1, 0)
        self.shape_d = d
        self.dof_s_within = np.maximum(st.n_shape - 1.0, 0.0) * d
        self._has_shape = st.n_shape > 0
        self._scatter2 = None if st.scatter is None else np.einsum("kst,ktu->ksu", st.scatter, st.scatter)
        q_s = 3 if np.all(self.dof_s_within[self._has_shape] >= 20) else n_quad
        inv_gs, self._logw_s = _variance_nodes(self.shape_prior, self.dof_s_within, q_s)
        self._inv_gs = inv_gs
        self.t_grid, self._t_logprior = _scale_grid(*shape_scale_range, n_grid)

    # -- the sampler's protocol ------------------------------------------------------------------
    @property
    def n_extra(self) -> int:
        return len(self.extra_names)

    def prepare_at_map(self, theta: np.ndarray) -> bool:
        return False

    def _variance_priors(self) -> list[InverseGamma]:
        m = len(self.mode_numbers)
        return [self.freq_prior] * m + ([self.shape_prior] * m if self.uses_shapes else [])

    def extra_logprior(self, extra: np.ndarray) -> np.ndarray:
        return log_variance_logprior(self._variance_priors(), extra, self.variance == "sampled")

    def extra_initial(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return log_variance_initial(self._variance_priors(), rng, n, self.variance == "sampled")

    # -- pieces ------------------------------------------------------------------------------------
    def _freq_terms(self, theta: np.ndarray, sigma2: np.ndarray | None):
        """Mean residual (B, m), variance nodes (B, m, Q), their log weights and the W term (B, m)."""
        st = self.stats
        fp, u, _ = paired_predictions(self.predictor, st, theta)
        ybar = self.xbar - fp / st.f_ref
        if sigma2 is None:
            nodes = np.broadcast_to(self._sigma2_nodes, (theta.shape[0],) + self._sigma2_nodes.shape)
            logw = self._logw_f[None]
            w_term = np.broadcast_to(self._c_f, ybar.shape)
        else:
            nodes, logw = sigma2[:, :, None], np.zeros((1, 1, 1))
            w_term = -0.5 * self.dof_f * (_LOG2PI + np.log(sigma2)) - 0.5 * self.w_f / sigma2
        return ybar, nodes, logw, w_term, u

    def _shape_terms(self, u: np.ndarray, tau2: np.ndarray | None):
        """Mean square per dimension of the mean shape residual (B, m), its noise nodes (B, m, Q),
        log weights, the within term (B, m) incl. the amplitude Jacobian, the within scatter."""
        st = self.stats
        assert st.scatter is not None and self._scatter2 is not None  # uses_shapes
        q1 = np.einsum("bsk,kst,btk->bk", u, st.scatter, u)
        q2 = np.einsum("bsk,kst,btk->bk", u, self._scatter2, u)
        amp = np.maximum(q1, 1e-300)
        z = np.maximum((q2 - q1 * q1) / amp, 0.0)  # A |e_hat|^2 = |(I - u u^T) S u|^2 / (u^T S u)
        within = np.maximum(st.norm2 - q1 - z, 0.0)
        e2 = z / amp / max(self.shape_d, 1)  # mean square per dimension of e_hat
        d = self.shape_d
        if tau2 is None:
            nodes = (self.shape_prior.scale + 0.5 * within)[:, :, None] * self._inv_gs[None]
            logw = self._logw_s[None]
            w_term = ig_marginal_loglik(within, self.dof_s_within, self.shape_prior)
        else:
            nodes, logw = tau2[:, :, None], np.zeros((1, 1, 1))
            w_term = -0.5 * self.dof_s_within * (_LOG2PI + np.log(tau2)) - 0.5 * within / tau2
        w_term = w_term - 0.5 * d * np.log(amp)
        return e2, nodes / amp[:, :, None], logw, w_term, within

    @staticmethod
    def _mixture(r2: np.ndarray, noise: np.ndarray, logw: np.ndarray, grid: np.ndarray,
                 logprior: np.ndarray, dim: float, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """log sum_j prior_j prod_k sum_i w_ki N_dim(mean residual_k; 0, (grid_j^2 + noise_ki) I)
        for mean-square residuals ``r2`` (B, m); also the per-grid log terms (B, G, m)."""
        # the quadrature nodes first, (Q, B, G, m): the sum over the few nodes is then a few
        # elementwise steps on whole slabs (numpy reduces a short last axis slowly)
        v = grid[:, None] ** 2 + np.ascontiguousarray(np.moveaxis(noise, 2, 0))[:, :, None]
        lg = -0.5 * dim * (_LOG2PI + np.log(v)) - 0.5 * dim * r2[None, :, None] / v
        per = logsumexp(lg + np.ascontiguousarray(np.moveaxis(logw, 2, 0))[:, :, None], axis=0) * mask
        return logsumexp(logprior[None] + per.sum(axis=2), axis=1), per

    def _freq_mixture(self, r2: np.ndarray) -> np.ndarray:
        """:meth:`_mixture` of the frequencies with the marginal's variance nodes (theta-free, their
        terms computed once)."""
        per = logsumexp(self._freq_const - r2[None, :, None] * self._freq_half_inv, axis=0)
        return logsumexp(self._s_logprior[None] + per.sum(axis=2), axis=1)

    def _split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        x = np.atleast_2d(x)
        theta = x[:, : self.n_theta] if self.n_theta else x
        if self.variance != "sampled":
            return theta, None, None
        m = len(self.mode_numbers)
        s2 = np.exp(x[:, self.n_theta:])
        return theta, s2[:, :m], (s2[:, m: 2 * m] if self.uses_shapes else None)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        theta, sigma2, tau2 = self._split(x)
        ybar, nodes, logw, w_term, u = self._freq_terms(theta, sigma2)
        if sigma2 is None:
            ll = self._freq_mixture(ybar**2)
        else:
            ll, _ = self._mixture(ybar**2, nodes / self.n_eff[None, :, None], logw, self.s_grid,
                                  self._s_logprior, 1.0, np.ones(ybar.shape[1]))
        ll = ll + w_term.sum(axis=1)
        if self.uses_shapes and self.shape_d > 0:
            e2, noise, lw, ws, _ = self._shape_terms(u, tau2)
            mask = self._has_shape.astype(float)
            lls, _ = self._mixture(e2, noise, lw, self.t_grid, self._t_logprior, float(self.shape_d), mask)
            ll = ll + lls + (ws * mask).sum(axis=1)
        return ll + self.log_jacobian

    # -- what the posterior reports ------------------------------------------------------------
    def _scale_posterior(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Posterior weights of the scale grid (G,), mean residuals (m,) and per-node terms at one theta."""
        theta = np.atleast_2d(theta)
        ybar, nodes, logw, _, _ = self._freq_terms(theta, None)
        noise = nodes / self.n_eff[None, :, None]
        _, per = self._mixture(ybar**2, noise, logw, self.s_grid, self._s_logprior, 1.0, np.ones(ybar.shape[1]))
        lp = self._s_logprior + per[0].sum(axis=1)
        return np.exp(lp - logsumexp(lp, axis=0)), ybar[0], noise[0]

    def variance_estimates(self, theta: np.ndarray) -> dict[str, float]:
        """At one theta: the posterior-mean error variances, the model-error scale ``s`` (and the
        shape scale ``t``), and each mode's systematic offset ``delta_k`` (posterior mean, relative:
        the data's mean frequency is about ``f_model (1 + delta_k)``) and its posterior std."""
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        out: dict[str, float] = {}
        for k, v in zip(self.mode_numbers, ig_posterior_mean(self.w_f, self.dof_f, self.freq_prior), strict=True):
            out[f"sigma2_f_mode{k}"] = float(v)
        pw, ybar, noise = self._scale_posterior(theta)
        out["model_error_scale"] = float(np.dot(pw, self.s_grid))
        s2 = self.s_grid**2
        for j, k in enumerate(self.mode_numbers):
            vk = float(np.median(noise[j]))  # sigma_k^2 / n_eff (its quadrature spread is small here)
            shrink = s2 / (s2 + vk)
            mean = float(np.dot(pw, shrink * ybar[j]))
            second = float(np.dot(pw, shrink * vk + (shrink * ybar[j]) ** 2))
            out[f"model_error_mode{k}"] = mean
            out[f"model_error_std_mode{k}"] = math.sqrt(max(second - mean * mean, 0.0))
            out[f"effective_windows_mode{k}"] = float(self.n_eff[j])
        if self.uses_shapes and self.shape_d > 0:
            _, u, _ = paired_predictions(self.predictor, self.stats, theta)
            e2, noise_s, lw, _, within = self._shape_terms(u, None)
            mask = self._has_shape.astype(float)
            _, per = self._mixture(e2, noise_s, lw, self.t_grid, self._t_logprior, float(self.shape_d), mask)
            lp = self._t_logprior + per[0].sum(axis=1)
            out["shape_error_scale"] = float(np.dot(np.exp(lp - logsumexp(lp, axis=0)), self.t_grid))
            tau2 = ig_posterior_mean(within[0], self.dof_s_within, self.shape_prior)
            for k, val in zip(self.mode_numbers, tau2, strict=True):
                out[f"sigma2_shape_mode{k}"] = float(val)
        return out

    def predictive_frequencies(self, theta_samples: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Frequencies (Hz) of a new window, one draw per row of ``theta_samples`` (S, m): the scale
        s, the error variance, the mode's offset delta_k and the window's scatter drawn from their
        posteriors given that theta (windows of the future are exchangeable with the data's)."""
        th = np.atleast_2d(np.asarray(theta_samples, dtype=float))
        st = self.stats
        out = np.empty((th.shape[0], len(self.mode_numbers)))
        for b in range(th.shape[0]):
            ybar, nodes, logw, _, _ = self._freq_terms(th[b:b + 1], None)
            noise = nodes[0] / self.n_eff[:, None]  # (m, Q)
            _, per = self._mixture(ybar**2, noise[None], logw, self.s_grid, self._s_logprior, 1.0,
                                   np.ones(ybar.shape[1]))
            lp = self._s_logprior + per[0].sum(axis=1)
            j = rng.choice(self.s_grid.size, p=np.exp(lp - logsumexp(lp, axis=0)))
            s2 = self.s_grid[j] ** 2
            for k in range(ybar.shape[1]):
                v = s2 + noise[k]
                lq = logw[0, k] - 0.5 * np.log(v) - 0.5 * ybar[0, k] ** 2 / v
                i = rng.choice(noise.shape[1], p=np.exp(lq - logsumexp(lq, axis=0)))
                nv = noise[k, i]
                mean = ybar[0, k] * s2 / (s2 + nv)
                var = s2 * nv / (s2 + nv)
                delta = mean + math.sqrt(var) * rng.standard_normal()
                sigma2 = nodes[0, k, i]
                r = self.xbar[k] - ybar[0, k]  # model frequency / f_ref
                out[b, k] = st.f_ref[k] * (r + delta + math.sqrt(sigma2) * rng.standard_normal())
        return out
