"""Likelihoods of modal data given theta, each evaluated for a batch of parameter vectors.

* :class:`GaussianModalLikelihood` - prediction-error model on tracked modal data: every window's
  relative frequency error of mode k is N(0, sigma_k^2) and every window's shape error at the
  sensors is N(0, tau_k^2 I) (after the best scaling of the model shape), windows independent given
  theta and the variances. The variances carry inverse-gamma priors and are either integrated out
  in closed form (``variance="marginal"``, the default) or sampled with theta (``"sampled"``, as
  log-variances).
* :class:`FitnessLikelihood` - the bridge paper's ``exp(-J(theta) / (2 k^2))`` with
  ``J = alpha * sum((f_obs - f_sim) / f_obs)^2 + beta * sum(1 - MAC)`` summed over modes and windows.
* :class:`~shm_ros.core.bayes.timedomain.TimeDomainLikelihood` (own module) - accelerations under a
  measured input.

Data enter only through sufficient statistics computed once (sums, and per-mode scatter matrices of
the shapes), so one evaluation costs a batched eigen-solution plus O(modes x sensors^2).
Model modes are paired with the data's modes by MAC for every theta (:mod:`.pairing`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import gammaln

from .forward import ModalPredictor
from .observations import ModalObservations
from .pairing import pair_modes
from .priors import Prior


@dataclass(frozen=True)
class InverseGamma:
    """Inverse-gamma prior IG(shape a, scale b) of an error variance."""

    shape: float
    scale: float

    @staticmethod
    def weak(typical_std: float, shape: float = 1.0) -> InverseGamma:
        """A weak prior whose mode is ``typical_std**2``."""
        return InverseGamma(shape, (shape + 1.0) * typical_std**2)


def ig_marginal_loglik(ss: np.ndarray, n: np.ndarray | float, prior: InverseGamma) -> np.ndarray:
    """log of  int N(r | 0, s2)^n IG(s2 | a, b) ds2  for residuals with sum of squares ``ss``."""
    a, b = prior.shape, prior.scale
    n = np.asarray(n, dtype=float)
    an = a + 0.5 * n
    return (a * math.log(b) - gammaln(a) + gammaln(an) - 0.5 * n * math.log(2 * math.pi)
            - an * np.log(b + 0.5 * ss))


def ig_posterior_mean(ss: np.ndarray, n: np.ndarray | float, prior: InverseGamma) -> np.ndarray:
    """Posterior mean of the variance given residual sum of squares ``ss`` of ``n`` values."""
    a = prior.shape + 0.5 * np.asarray(n, dtype=float)
    return np.where(a > 1, (prior.scale + 0.5 * ss) / np.maximum(a - 1, 1e-12), np.nan)


@dataclass
class ModalStatistics:
    """Sufficient statistics of tracked modal data for the modal likelihoods."""

    f_ref: np.ndarray  # (m,) mean observed frequency per mode
    n_freq: np.ndarray  # (m,) windows with that mode
    s1: np.ndarray  # (m,) sum f/f_ref
    s2: np.ndarray  # (m,) sum (f/f_ref)^2
    inv1: np.ndarray  # (m,) sum 1/f
    inv2: np.ndarray  # (m,) sum 1/f^2
    phi_ref: np.ndarray | None  # (m, s) reference shapes for pairing
    n_shape: np.ndarray  # (m,) windows with a complete shape
    scatter: np.ndarray | None  # (m, s, s) sum phi phi^T
    norm2: np.ndarray  # (m,) sum |phi|^2
    scatter_unit: np.ndarray | None  # (m, s, s) sum phi phi^T / |phi|^2 (for MAC sums)

    @staticmethod
    def from_observations(obs: ModalObservations, use_shapes: bool = True) -> ModalStatistics:
        f = obs.frequencies_hz
        present = np.isfinite(f) & (f > 0)
        n_freq = present.sum(axis=0).astype(float)
        if np.any(n_freq == 0):
            empty = [obs.mode_numbers[k] for k in np.flatnonzero(n_freq == 0)]
            raise ValueError(f"mode(s) {empty} have no frequency in any window")
        fz = np.where(present, f, 0.0)
        f_ref = fz.sum(axis=0) / n_freq
        x = fz / f_ref
        with np.errstate(divide="ignore"):
            inv = np.where(present, 1.0 / np.where(present, f, 1.0), 0.0)
        m = obs.n_modes
        phi_ref = scatter = scatter_unit = None
        n_shape = np.zeros(m)
        norm2 = np.zeros(m)
        if use_shapes and obs.has_shapes:
            assert obs.shapes is not None
            s = len(obs.sensor_ids)
            scatter = np.zeros((m, s, s))
            scatter_unit = np.zeros((m, s, s))
            for k in range(m):
                rows = obs.shapes[:, k, :]
                ok = np.all(np.isfinite(rows), axis=1) & present[:, k]
                rows = rows[ok]
                nrm = np.sum(rows**2, axis=1)
                keep = nrm > 0
                rows, nrm = rows[keep], nrm[keep]
                n_shape[k] = rows.shape[0]
                scatter[k] = rows.T @ rows
                scatter_unit[k] = (rows / nrm[:, None]).T @ rows
                norm2[k] = nrm.sum()
            phi_ref = obs.reference_shapes()
            if phi_ref is not None:
                phi_ref = np.where(np.isfinite(phi_ref), phi_ref, np.nan)
        return ModalStatistics(f_ref, n_freq, x.sum(axis=0), (x**2).sum(axis=0), inv.sum(axis=0),
                               (inv**2).sum(axis=0), phi_ref, n_shape, scatter, norm2, scatter_unit)

    @property
    def n_sensors(self) -> int:
        return 0 if self.scatter is None else int(self.scatter.shape[1])

    @property
    def uses_shapes(self) -> bool:
        return self.scatter is not None and bool(np.any(self.n_shape > 0))


def paired_predictions(predictor: ModalPredictor, stats: ModalStatistics, theta: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Model frequencies (B, m) and unit shapes at sensors (B, s, m) paired to the data's modes."""
    f, phi = predictor(theta)
    idx = pair_modes(stats.f_ref, stats.phi_ref, f, phi if stats.phi_ref is not None else None)
    fp = np.take_along_axis(f, idx, axis=1)
    php = np.take_along_axis(phi, idx[:, None, :], axis=2)
    nrm = np.sqrt(np.sum(php**2, axis=1, keepdims=True))
    return fp, php / np.where(nrm > 0, nrm, 1.0), idx


class _ModalLikelihoodBase:
    """Common part: a predictor, the statistics, and how many extra (nuisance) columns are sampled."""

    extra_names: list[str] = []

    def __init__(self, predictor: ModalPredictor, obs: ModalObservations, use_shapes: bool = True):
        if use_shapes and obs.has_shapes and list(predictor.sensor_ids) != list(obs.sensor_ids):
            raise ValueError("predictor sensors must be the data's sensors in the same order: "
                             f"{predictor.sensor_ids} vs {obs.sensor_ids}")
        self.predictor = predictor
        self.stats = ModalStatistics.from_observations(obs, use_shapes=use_shapes)
        if predictor.n_modes < len(self.stats.f_ref):
            raise ValueError(f"the model offers {predictor.n_modes} modes but the data track "
                             f"{len(self.stats.f_ref)}")
        self.n_theta = 0  # set by the caller (number of structural parameters)

    @property
    def n_extra(self) -> int:
        return len(self.extra_names)

    def extra_logprior(self, extra: np.ndarray) -> np.ndarray:
        return np.zeros(extra.shape[0])

    def extra_initial(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return np.zeros((n, 0))

    def _residual_ss(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        st = self.stats
        fp, u, _ = paired_predictions(self.predictor, st, theta)
        r = fp / st.f_ref
        ss_f = st.s2 - 2.0 * r * st.s1 + st.n_freq * r * r
        ss_f = np.maximum(ss_f, 0.0)
        if not st.uses_shapes:
            return ss_f, None
        assert st.scatter is not None  # uses_shapes implies the scatter matrices exist
        proj = np.einsum("bsk,kst,btk->bk", u, st.scatter, u)
        return ss_f, np.maximum(st.norm2 - proj, 0.0)


class GaussianModalLikelihood(_ModalLikelihoodBase):
    """Gaussian prediction error on frequencies and shapes with inverse-gamma variance priors."""

    def __init__(self, predictor: ModalPredictor, obs: ModalObservations, *, use_shapes: bool = True,
                 variance: str = "marginal", freq_prior: InverseGamma | None = None,
                 shape_prior: InverseGamma | None = None):
        super().__init__(predictor, obs, use_shapes)
        if variance not in ("marginal", "sampled"):
            raise ValueError(f"variance must be 'marginal' or 'sampled', got {variance!r}")
        self.variance = variance
        self.freq_prior = freq_prior or InverseGamma.weak(0.01)
        self.shape_prior = shape_prior or InverseGamma.weak(0.05)
        st = self.stats
        self.mode_numbers = list(obs.mode_numbers)
        # dimension of each mode's shape residual: the scale of the model shape is fitted per window
        self.shape_dof = st.n_shape * max(st.n_sensors - 1, 0)
        self.log_jacobian = -float(np.sum(st.n_freq * np.log(st.f_ref)))
        names = [f"sigma2_f_mode{k}" for k in self.mode_numbers]
        if st.uses_shapes:
            names += [f"sigma2_shape_mode{k}" for k in self.mode_numbers]
        self.variance_names = names
        self.extra_names = [f"log_{n}" for n in names] if variance == "sampled" else []

    # nuisance columns (sampled variances) ---------------------------------------------------------
    def _variance_priors(self) -> list[InverseGamma]:
        m = len(self.mode_numbers)
        pri = [self.freq_prior] * m
        if self.stats.uses_shapes:
            pri += [self.shape_prior] * m
        return pri

    def extra_logprior(self, extra: np.ndarray) -> np.ndarray:
        if self.variance != "sampled":
            return np.zeros(extra.shape[0])
        out = np.zeros(extra.shape[0])
        for j, p in enumerate(self._variance_priors()):
            z = extra[:, j]
            out += Prior.make("inverse_gamma", {"shape": p.shape, "scale": p.scale}).logpdf(np.exp(z)) + z
        return out

    def extra_initial(self, rng: np.random.Generator, n: int) -> np.ndarray:
        if self.variance != "sampled":
            return np.zeros((n, 0))
        # start at the prior modes (spread a little); burn-in moves them to the data's scatter
        cols = [np.log(p.scale / (p.shape + 1.0)) + 0.3 * rng.standard_normal(n)
                for p in self._variance_priors()]
        return np.column_stack(cols)

    def variance_estimates(self, theta: np.ndarray) -> dict[str, float]:
        """Posterior-mean variances given one theta (reported next to the parameters)."""
        ss_f, ss_s = self._residual_ss(np.atleast_2d(theta))
        vals = list(ig_posterior_mean(ss_f[0], self.stats.n_freq, self.freq_prior))
        if ss_s is not None:
            vals += list(ig_posterior_mean(ss_s[0], self.shape_dof, self.shape_prior))
        return dict(zip(self.variance_names, (float(v) for v in vals), strict=True))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(x)
        theta = x[:, : self.n_theta] if self.n_theta else x
        ss_f, ss_s = self._residual_ss(theta)
        st = self.stats
        if self.variance == "marginal":
            ll = ig_marginal_loglik(ss_f, st.n_freq, self.freq_prior).sum(axis=1)
            if ss_s is not None:
                ll = ll + ig_marginal_loglik(ss_s, self.shape_dof, self.shape_prior).sum(axis=1)
            return ll + self.log_jacobian
        m = len(self.mode_numbers)
        s2 = np.exp(x[:, self.n_theta:])
        ll = (-0.5 * st.n_freq * np.log(2 * np.pi * s2[:, :m]) - 0.5 * ss_f / s2[:, :m]).sum(axis=1)
        if ss_s is not None:
            t2 = s2[:, m: 2 * m]
            ll = ll + (-0.5 * self.shape_dof * np.log(2 * np.pi * t2) - 0.5 * ss_s / t2).sum(axis=1)
        return ll + self.log_jacobian


class FitnessLikelihood(_ModalLikelihoodBase):
    """The bridge paper's fitness likelihood ``exp(-J / (2 k^2))``, J summed over the windows."""

    def __init__(self, predictor: ModalPredictor, obs: ModalObservations, *, alpha: float = 0.5,
                 beta: float = 0.5, k: float = 0.05):
        if alpha < 0 or beta < 0 or alpha + beta <= 0:
            raise ValueError(f"fitness weights need alpha, beta >= 0 and alpha + beta > 0, got "
                             f"({alpha}, {beta})")
        if k <= 0:
            raise ValueError(f"fitness tolerance k must be > 0, got {k}")
        super().__init__(predictor, obs, use_shapes=beta > 0)
        self.alpha, self.beta, self.k = float(alpha), float(beta), float(k)
        self.extra_names = []

    def fitness(self, theta: np.ndarray) -> np.ndarray:
        st = self.stats
        fp, u, _ = paired_predictions(self.predictor, st, np.atleast_2d(theta))
        j_f = (st.n_freq - 2.0 * fp * st.inv1 + fp * fp * st.inv2).sum(axis=1)
        J = self.alpha * j_f
        if self.beta > 0 and st.uses_shapes:
            assert st.scatter_unit is not None  # built together with scatter
            mac_sum = np.einsum("bsk,kst,btk->bk", u, st.scatter_unit, u)
            J = J + self.beta * (st.n_shape - mac_sum).sum(axis=1)
        return J

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(x)
        theta = x[:, : self.n_theta] if self.n_theta else x
        return -self.fitness(theta) / (2.0 * self.k**2)
