"""Likelihoods of modal data given theta, each evaluated for a batch of parameter vectors.

* :class:`GaussianModalLikelihood` - prediction-error model on tracked modal data: every window's
  relative frequency error of mode k is N(0, sigma_k^2) and every window's shape error at the
  sensors is N(0, tau_k^2 I) (after the best scaling of the model shape), windows independent given
  theta and the variances. The variances carry inverse-gamma priors and are either integrated out
  in closed form (``variance="marginal"``, the default) or sampled with theta (``"sampled"``, as
  log-variances).
  Optionally (``use_damping``) every window's relative damping-ratio error is N(0, varsigma_k^2)
  too, the model's ratio coming from its damping law (Rayleigh ratios at the model frequencies).
* :class:`FitnessLikelihood` - the bridge paper's ``exp(-J(theta) / (2 k^2))`` with
  ``J = alpha * sum((f_obs - f_sim) / f_obs)^2 + beta * sum(1 - MAC)`` over modes, and over the
  windows either summed (``j="summed"``) or averaged (``j="averaged"``, J then does not grow with
  the number of windows, so the prior keeps its weight as in the paper's Table 1).
* :class:`~shm_ros.core.bayes.timedomain.TimeDomainLikelihood` (own module) - accelerations under a
  measured input.

Data enter only through sufficient statistics computed once (sums, and per-mode scatter matrices of
the shapes), so one evaluation costs a batched eigen-solution plus O(modes x sensors^2).
Model modes are paired with the data's modes once, outside the likelihood (:mod:`.pairing`): the
statistics carry the model-mode index of every data mode (``ModalStatistics.model_index``) and
:func:`paired_predictions` reads the model at those indices for every theta.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Any, TypedDict

import numpy as np
from scipy.special import gammaln

from shm_ros.core.observations import ModalObservations
from shm_ros.core.priors import Prior

from .forward import ModalPredictor
from .likelihood_kinds.base import NoNuisance
from .pairing import pair_modes_optimal


@dataclass(frozen=True)
class InverseGamma:
    """Inverse-gamma prior IG(shape a, scale b) of an error variance."""

    shape: float
    scale: float

    @staticmethod
    def weak(typical_std: float, shape: float = 1.0) -> InverseGamma:
        """A weak prior whose mode is ``typical_std**2``."""
        return InverseGamma(shape, (shape + 1.0) * typical_std**2)


class ErrorPriors(TypedDict):
    freq_prior: InverseGamma
    shape_prior: InverseGamma


def weak_error_priors(config: Any) -> ErrorPriors:
    """The weak inverse-gamma priors of the frequency and shape error variances an
    :class:`~shm_ros.core.bayes.update.UpdateConfig` asks for (keyword arguments of the likelihoods)."""
    return ErrorPriors(freq_prior=InverseGamma.weak(config.frequency_error_guess, config.ig_shape),
                       shape_prior=InverseGamma.weak(config.shape_error_guess, config.ig_shape))


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


def log_variance_logprior(priors: list[InverseGamma], extra: np.ndarray, sampled: bool) -> np.ndarray:
    """Log prior of sampled log-variances ``extra`` (B, len(priors)): each IG prior of a variance
    carried to its logarithm (+ log-Jacobian); zero when the variances are integrated out."""
    out = np.zeros(extra.shape[0])
    if not sampled:
        return out
    for j, p in enumerate(priors):
        z = extra[:, j]
        out += Prior.make("inverse_gamma", {"shape": p.shape, "scale": p.scale}).logpdf(np.exp(z)) + z
    return out


def log_variance_initial(priors: list[InverseGamma], rng: np.random.Generator, n: int, sampled: bool) -> np.ndarray:
    """Starting log-variances (n, len(priors)): the prior modes, spread a little (burn-in moves them
    to the data's scatter); no columns when the variances are integrated out."""
    if not sampled:
        return np.zeros((n, 0))
    return np.column_stack([np.log(p.scale / (p.shape + 1.0)) + 0.3 * rng.standard_normal(n) for p in priors])


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
    # model mode (0-based, ascending model frequency) of every data mode: the fixed pairing
    # (None until set; :func:`paired_predictions` then pairs once at the nominal model)
    model_index: np.ndarray | None = None
    damping: DampingStatistics | None = None  # only when damping enters the likelihood

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
    def pairing(self) -> np.ndarray:
        if self.model_index is None:
            raise ValueError("the modal statistics carry no pairing yet")
        return self.model_index

    @property
    def n_sensors(self) -> int:
        return 0 if self.scatter is None else int(self.scatter.shape[1])

    @property
    def uses_shapes(self) -> bool:
        return self.scatter is not None and bool(np.any(self.n_shape > 0))


@dataclass
class DampingStatistics:
    """Sums of the observed damping ratios per mode, relative to their mean ``z_ref``."""

    z_ref: np.ndarray  # (m,) mean observed ratio (NaN: mode without damping data)
    n: np.ndarray  # (m,) windows with a ratio
    s1: np.ndarray  # (m,) sum z / z_ref
    s2: np.ndarray  # (m,) sum (z / z_ref)^2

    @staticmethod
    def from_observations(obs: ModalObservations) -> DampingStatistics:
        if obs.damping is None:
            raise ValueError("damping in the likelihood needs damping ratios in the modal data")
        z = obs.damping
        ok = np.isfinite(z) & (z > 0)
        n = ok.sum(axis=0).astype(float)
        if not np.any(n > 0):
            raise ValueError("damping in the likelihood needs damping ratios in the modal data")
        zz = np.where(ok, z, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            z_ref = np.where(n > 0, zz.sum(axis=0) / np.maximum(n, 1), np.nan)
            x = np.where(ok, zz / np.where(n > 0, z_ref, 1.0), 0.0)
        return DampingStatistics(z_ref, n, x.sum(axis=0), (x**2).sum(axis=0))


def _pair_at_nominal(predictor: ModalPredictor, stats: ModalStatistics) -> np.ndarray:
    """Fallback for statistics built without a pairing: the optimal assignment at the nominal model,
    computed once (the updating itself pairs behind a gate, :func:`shm_ros.core.bayes.update.update`)."""
    model = getattr(predictor, "model", None)
    theta0 = model.nominal_theta() if model is not None else None
    if theta0 is None:
        raise ValueError("the statistics carry no pairing and the predictor has no nominal model")
    f, phi = predictor(theta0[None])
    use = stats.phi_ref is not None and phi.shape[1] > 0 and np.all(np.isfinite(stats.phi_ref))
    return pair_modes_optimal(stats.f_ref, stats.phi_ref if use else None, f[0], phi[0] if use else None)


def paired_predictions(predictor: ModalPredictor, stats: ModalStatistics, theta: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Model frequencies (B, m) and unit shapes at sensors (B, s, m) paired to the data's modes.

    The pairing is the fixed ``stats.model_index`` (set once, outside the likelihood); the third
    value is that index broadcast to (B, m).
    """
    if stats.model_index is None:
        stats.model_index = _pair_at_nominal(predictor, stats)
    f, phi = predictor(theta)
    idx = np.broadcast_to(stats.model_index, (f.shape[0], stats.model_index.size))
    fp = f[:, stats.model_index]
    php = phi[:, :, stats.model_index]
    nrm = np.sqrt(np.sum(php**2, axis=1, keepdims=True))
    return fp, php / np.where(nrm > 0, nrm, 1.0), idx


def predicted_damping(predictor: ModalPredictor, theta: np.ndarray, frequencies_hz: np.ndarray,
                      model_index: np.ndarray) -> np.ndarray:
    """Damping ratios (B, m) of the paired model modes under the model's damping law (Rayleigh:
    fixed by the lowest two model modes at each theta; modal: the listed ratios)."""
    model = getattr(predictor, "model", None)
    if model is None:
        raise ValueError("damping in the likelihood needs a predictor that carries its model")
    z = model.modal_damping_ratios_batch(np.atleast_2d(theta), frequencies_hz)
    return z[:, model_index]


class _ModalLikelihoodBase(NoNuisance):
    """Common part: a predictor, the statistics, and how many extra (nuisance) columns are sampled."""

    extra_names: list[str] = []

    def __init__(self, predictor: ModalPredictor, obs: ModalObservations, use_shapes: bool = True,
                 pairing: np.ndarray | None = None, n_theta: int = 0):
        if use_shapes and obs.has_shapes and list(predictor.sensor_ids) != list(obs.sensor_ids):
            raise ValueError("predictor sensors must be the data's sensors in the same order: "
                             f"{predictor.sensor_ids} vs {obs.sensor_ids}")
        self.predictor = predictor
        self.stats = ModalStatistics.from_observations(obs, use_shapes=use_shapes)
        if predictor.n_modes < len(self.stats.f_ref):
            raise ValueError(f"the model offers {predictor.n_modes} modes but the data track "
                             f"{len(self.stats.f_ref)}")
        if pairing is not None:
            set_pairing(self, pairing)
        self.n_theta = n_theta  # structural parameters (0: every column of x is one)


    def _residuals(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """Sums of squares (B, m) of the relative frequency, shape and (when the statistics hold
        damping) relative damping residuals over the windows."""
        st = self.stats
        if st.damping is not None:
            f_all, _ = self.predictor(theta)  # the damping law needs the lowest modes too
        fp, u, _ = paired_predictions(self.predictor, st, theta)
        r = fp / st.f_ref
        ss_f = st.s2 - 2.0 * r * st.s1 + st.n_freq * r * r
        ss_f = np.maximum(ss_f, 0.0)
        ss_d = None
        if st.damping is not None:
            dm = st.damping
            z = predicted_damping(self.predictor, theta, f_all, st.pairing)
            rz = z / np.where(dm.n > 0, dm.z_ref, 1.0)
            ss_d = np.where(dm.n > 0, np.maximum(dm.s2 - 2.0 * rz * dm.s1 + dm.n * rz * rz, 0.0), 0.0)
        if not st.uses_shapes:
            return ss_f, None, ss_d
        assert st.scatter is not None  # uses_shapes implies the scatter matrices exist
        proj = np.einsum("bsk,kst,btk->bk", u, st.scatter, u)
        return ss_f, np.maximum(st.norm2 - proj, 0.0), ss_d


def set_pairing(likelihood: object, model_index: np.ndarray) -> None:
    """Fix the model mode of every data mode of a modal likelihood (one that holds ``stats``)."""
    stats = getattr(likelihood, "stats", None)
    if not isinstance(stats, ModalStatistics):
        raise TypeError(f"{type(likelihood).__name__} holds no modal statistics to pair")
    idx = np.asarray(model_index, dtype=int)
    if idx.shape != stats.f_ref.shape:
        raise ValueError(f"pairing gives {idx.size} model modes for {stats.f_ref.size} data modes")
    n_model = getattr(getattr(likelihood, "predictor", None), "n_modes", None)
    if n_model is not None and idx.size and int(idx.max()) >= n_model:
        raise ValueError(f"pairing uses model mode {int(idx.max()) + 1} but the predictor offers {n_model}")
    stats.model_index = idx


class GaussianModalLikelihood(_ModalLikelihoodBase):
    """Gaussian prediction error on frequencies and shapes (and optionally damping ratios) with
    inverse-gamma variance priors."""

    def __init__(self, predictor: ModalPredictor, obs: ModalObservations, *, use_shapes: bool = True,
                 variance: str = "marginal", freq_prior: InverseGamma | None = None,
                 shape_prior: InverseGamma | None = None, use_damping: bool = False,
                 damping_prior: InverseGamma | None = None, pairing: np.ndarray | None = None,
                 n_theta: int = 0):
        super().__init__(predictor, obs, use_shapes, pairing, n_theta)
        if variance not in ("marginal", "sampled"):
            raise ValueError(f"variance must be 'marginal' or 'sampled', got {variance!r}")
        self.variance = variance
        self.freq_prior = freq_prior or InverseGamma.weak(0.01)
        self.shape_prior = shape_prior or InverseGamma.weak(0.05)
        # identified damping scatters far more than frequencies: tens of percent per window
        self.damping_prior = damping_prior or InverseGamma.weak(0.3)
        st = self.stats
        if use_damping:
            st.damping = DampingStatistics.from_observations(obs)
        self.mode_numbers = list(obs.mode_numbers)
        # dimension of each mode's shape residual: the scale of the model shape is fitted per window
        self.shape_dof = st.n_shape * max(st.n_sensors - 1, 0)
        self.log_jacobian = -float(np.sum(st.n_freq * np.log(st.f_ref)))
        names = [f"sigma2_f_mode{k}" for k in self.mode_numbers]
        if st.uses_shapes:
            names += [f"sigma2_shape_mode{k}" for k in self.mode_numbers]
        if st.damping is not None:
            dm = st.damping
            self.log_jacobian -= float(np.sum(np.where(dm.n > 0, dm.n * np.log(np.where(dm.n > 0, dm.z_ref, 1.0)),
                                                       0.0)))
            names += [f"sigma2_damping_mode{k}" for k in self.mode_numbers]
        self.variance_names = names
        self.extra_names = [f"log_{n}" for n in names] if variance == "sampled" else []

    # nuisance columns (sampled variances) ---------------------------------------------------------
    def _variance_priors(self) -> list[InverseGamma]:
        m = len(self.mode_numbers)
        pri = [self.freq_prior] * m
        if self.stats.uses_shapes:
            pri += [self.shape_prior] * m
        if self.stats.damping is not None:
            pri += [self.damping_prior] * m
        return pri

    def _blocks(self, theta: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, InverseGamma]]:
        """(sum of squares (B, m), residual count (m,), variance prior) per error kind, in the order
        of ``variance_names``."""
        ss_f, ss_s, ss_d = self._residuals(theta)
        st = self.stats
        out = [(ss_f, st.n_freq, self.freq_prior)]
        if ss_s is not None:
            out.append((ss_s, self.shape_dof, self.shape_prior))
        if ss_d is not None:
            assert st.damping is not None  # ss_d exists only with damping statistics
            out.append((ss_d, st.damping.n, self.damping_prior))
        return out

    def extra_logprior(self, extra: np.ndarray) -> np.ndarray:
        return log_variance_logprior(self._variance_priors(), extra, self.variance == "sampled")

    def extra_initial(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return log_variance_initial(self._variance_priors(), rng, n, self.variance == "sampled")

    def variance_estimates(self, theta: np.ndarray) -> dict[str, float]:
        """Posterior-mean variances given one theta (reported next to the parameters)."""
        vals: list[float] = []
        for ss, n, prior in self._blocks(np.atleast_2d(theta)):
            vals += [float(v) for v in ig_posterior_mean(ss[0], n, prior)]
        return dict(zip(self.variance_names, vals, strict=True))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(x)
        theta = x[:, : self.n_theta] if self.n_theta else x
        blocks = self._blocks(theta)
        ll = np.zeros(x.shape[0])
        if self.variance == "marginal":
            for ss, n, prior in blocks:
                # a mode without residuals (no damping data) contributes exactly 0
                ll = ll + np.where(np.asarray(n) > 0, ig_marginal_loglik(ss, n, prior), 0.0).sum(axis=1)
            return ll + self.log_jacobian
        m = len(self.mode_numbers)
        s2 = np.exp(x[:, self.n_theta:])
        for b, (ss, n, _) in enumerate(blocks):
            v = s2[:, b * m: (b + 1) * m]
            ll = ll + (-0.5 * n * np.log(2 * np.pi * v) - 0.5 * ss / v).sum(axis=1)
        return ll + self.log_jacobian


class FitnessJ(enum.StrEnum):
    """How the fitness J combines the windows."""

    SUMMED = "summed"  # every window adds to J: the likelihood sharpens with more windows
    AVERAGED = "averaged"  # the mean over windows: J of one typical window, the prior keeps its weight


class FitnessLikelihood(_ModalLikelihoodBase):
    """The bridge paper's fitness likelihood ``exp(-J / (2 k^2))``, J summed or averaged over windows."""

    def __init__(self, predictor: ModalPredictor, obs: ModalObservations, *, alpha: float = 0.5,
                 beta: float = 0.5, k: float = 0.05, j: str = FitnessJ.SUMMED.value,
                 pairing: np.ndarray | None = None, n_theta: int = 0):
        if alpha < 0 or beta < 0 or alpha + beta <= 0:
            raise ValueError(f"fitness weights need alpha, beta >= 0 and alpha + beta > 0, got "
                             f"({alpha}, {beta})")
        if k <= 0:
            raise ValueError(f"fitness tolerance k must be > 0, got {k}")
        if j not in tuple(FitnessJ):
            raise ValueError(f"fitness J must be one of {[m.value for m in FitnessJ]}, got {j!r}")
        super().__init__(predictor, obs, beta > 0, pairing, n_theta)
        self.alpha, self.beta, self.k = float(alpha), float(beta), float(k)
        self.j = FitnessJ(j)
        self.extra_names = []

    def fitness(self, theta: np.ndarray) -> np.ndarray:
        st = self.stats
        fp, u, _ = paired_predictions(self.predictor, st, np.atleast_2d(theta))
        j_f = st.n_freq - 2.0 * fp * st.inv1 + fp * fp * st.inv2  # (B, m) per-mode sums over windows
        if self.j is FitnessJ.AVERAGED:
            j_f = j_f / st.n_freq
        J = self.alpha * j_f.sum(axis=1)
        if self.beta > 0 and st.uses_shapes:
            assert st.scatter_unit is not None  # built together with scatter
            j_s = st.n_shape - np.einsum("bsk,kst,btk->bk", u, st.scatter_unit, u)
            if self.j is FitnessJ.AVERAGED:
                j_s = np.where(st.n_shape > 0, j_s / np.maximum(st.n_shape, 1.0), 0.0)
            J = J + self.beta * j_s.sum(axis=1)
        return J

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(x)
        theta = x[:, : self.n_theta] if self.n_theta else x
        return -self.fitness(theta) / (2.0 * self.k**2)
