"""One call from a model, data and settings to a posterior: ``update(model, observations, config)``.

The CLI (``shm-ros update``), the ROS node and ``explain`` all call :func:`update`; it assembles a
predictor (full or IIRS-reduced), pairs the data's modes with the model's once behind a gate (at the
prior mean, again once at the MAP; :mod:`.pairing`), builds the likelihood and the joint prior,
finds the MAP, samples with MH or emcee until the ArviZ diagnostics are met, estimates the evidence
by nested sampling and summarises. Observed modes that pair with no model mode are left out and
reported (``Posterior.unmodelled_modes``, ``warnings``).
"""

from __future__ import annotations

import enum
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from shm_ros.core.config import check_choice, option
from shm_ros.core.modal import mac, unit_max
from shm_ros.core.models.base import AffineModel

from .evidence import nested_evidence
from .fit import modal_fit
from .forward import build_predictor
from .likelihoods import FitnessJ, FitnessLikelihood, GaussianModalLikelihood, InverseGamma, set_pairing
from .model_error import ModelErrorLikelihood
from shm_ros.core.observations import ModalObservations
from .pairing import DEFAULT_MAC_GATE, ModePairing, PairingGate, UnmodelledMode, pair_with_model, select_modes
from shm_ros.core.priors import JointPrior, Prior, PriorError, priors_from_specs
from .records import JointTimeDomainLikelihood
from .samplers import ChainResult, SamplerSettings, find_map, laplace_covariance, run_sampler
from .timedomain import TimeDomainLikelihood


class Likelihood(enum.StrEnum):
    MODEL_ERROR = "model-error"  # modal data with a systematic model error shared by the windows
    GAUSSIAN = "gaussian"  # Gaussian prediction error on modal data, windows independent
    FITNESS = "fitness"  # the bridge paper's exp(-J / 2k^2)
    TIME = "time"  # accelerations under the measured input


class Sampler(enum.StrEnum):
    EMCEE = "emcee"  # affine-invariant ensemble
    MH = "mh"  # adaptive Metropolis-Hastings


class Variance(enum.StrEnum):  # prediction-error variances of the Gaussian likelihood
    MARGINAL = "marginal"  # integrated out
    SAMPLED = "sampled"


class Reduction(enum.StrEnum):
    AUTO = "auto"  # IIRS when sensors are fewer than DOFs and it is exact and cheaper
    IIRS = "iirs"
    NONE = "none"


LIKELIHOODS = tuple(m.value for m in Likelihood)
SAMPLERS = tuple(m.value for m in Sampler)


@dataclass
class UpdateConfig:
    """Settings of one updating run (every field has a default; all are plain data)."""

    likelihood: str = option(Likelihood.MODEL_ERROR.value, "model-error: modal data with a systematic "
                             "model error shared by all windows (docs/updating.md); gaussian: windows "
                             "independent; the bridge paper's fitness exp(-J/2k^2); or time: "
                             "accelerations under the measured input", choices=Likelihood)
    sampler: str = option(Sampler.EMCEE.value, "emcee ensemble or adaptive Metropolis-Hastings",
                          choices=Sampler)
    # priors by parameter name: {"dist": "normal", "mean": 1.0, "std": 0.1}; None = from the model
    # caller (``priors`` argument of :func:`update`); not an option: the structure file has them
    priors: dict[str, dict[str, Any]] | None = None
    n_modes: int | None = option(None, "model modes offered to pairing (unset: the data's modes + 2)")
    use_shapes: bool = option(True, "use mode shapes (false: frequencies only)")
    reduction: str = option(Reduction.AUTO.value, "IIRS reduction to the measured DOFs (auto: when "
                            "sensors are fewer than DOFs)", choices=Reduction)
    variance: str = option(Variance.MARGINAL.value, "prediction-error variances (inverse-gamma "
                           "priors): integrated out or sampled", choices=Variance)
    ig_shape: float = option(1.0, "shape of the inverse-gamma priors of the error variances")
    frequency_error_guess: float = option(0.01, "prior mode of the relative frequency error std")
    shape_error_guess: float = option(0.05, "prior mode of the shape error std")
    use_damping: bool = option(False, "gaussian likelihood: damping ratios enter too (model ratios from "
                               "the structure's damping law, e.g. Rayleigh at the model frequencies)")
    damping_error_guess: float = option(0.3, "prior mode of the relative damping-ratio error std")
    residual_ar_order: int = option(2, "time likelihood: order of the autoregressive model of the "
                                    "residuals (0: independent samples)")
    alpha: float = option(0.5, "fitness likelihood: weight of the frequencies")
    beta: float = option(0.5, "fitness likelihood: weight of 1 - MAC")
    k: float = option(0.05, "fitness likelihood: tolerance k")
    fitness_j: str = option(FitnessJ.SUMMED.value, "fitness likelihood: J summed over the windows "
                            "(each window is evidence) or averaged (J of one typical window, as in the "
                            "bridge paper's Table 1)", choices=FitnessJ)
    frequency_gate: float = option(0.0, "pairing: largest relative distance between an observed and "
                                   "its model mode's frequency (0 = automatic: 10 % + 1.5 x the largest "
                                   "prior coefficient of variation, within 15-25 %)")
    mac_gate: float = option(DEFAULT_MAC_GATE, "pairing: smallest MAC between an observed mode's "
                             "shape and its model mode's (when the data have shapes)")
    pair_at_map: bool = option(True, "pair the observed modes again once at the MAP (same gate) and "
                               "search the MAP again if the pairing changed")
    n_chains: int = option(0, "walkers / chains (0 = automatic)")
    n_steps: int = option(1500, "first run length before the diagnostics are checked")
    max_steps: int = option(20000, "upper bound on steps")
    burn_in: int = option(0, "Metropolis-Hastings adaptation steps (0 = automatic)")
    rhat_target: float = option(1.01, "R-hat target")
    ess_target: float = option(1000.0, "effective sample size target per parameter")
    evidence: bool = option(True, "estimate the log evidence by nested sampling")
    n_live: int = option(300, "live points of nested sampling")
    seed: int = option(0, "random seed")
    # the batched small-matrix algebra is fastest single-threaded (several threads per tiny
    # eigenproblem only contend)
    blas_threads: int = option(1, "BLAS threads during the run (0 = the library default)")
    # MAP, fit and evidence always use the exact predictor
    ritz: bool = option(True, "large full models: sample with a Rayleigh-Ritz projection when it "
                        "matches the full model to 1e-7 around the MAP (checked)")

    def validate(self) -> None:
        check_choice("update", "likelihood", self.likelihood, Likelihood)
        check_choice("update", "sampler", self.sampler, Sampler)
        check_choice("update", "reduction", self.reduction, Reduction)
        check_choice("update", "variance", self.variance, Variance)
        check_choice("update", "fitness_j", self.fitness_j, FitnessJ)
        if self.use_damping and self.likelihood != Likelihood.GAUSSIAN.value:
            raise ValueError(f"update: use_damping needs likelihood 'gaussian' (damping ratios enter only that "
                             f"likelihood), got likelihood {self.likelihood!r}")
        if self.frequency_gate < 0 or not 0 <= self.mac_gate < 1:
            raise ValueError(f"update: frequency_gate must be >= 0 (0 = automatic) and mac_gate in "
                             f"[0, 1), got {self.frequency_gate}, {self.mac_gate}")


@dataclass
class ParameterSummary:
    map: float
    mean: float
    std: float
    ci95: tuple[float, float]
    median: float

    def to_dict(self) -> dict[str, Any]:
        return {"map": self.map, "mean": self.mean, "std": self.std, "ci95": list(self.ci95),
                "median": self.median}


@dataclass
class Posterior:
    """Result of :func:`update`. ``samples`` are the kept draws of the structural parameters."""

    parameter_names: list[str]
    parameters: dict[str, ParameterSummary]
    samples: np.ndarray  # (n_samples, d)
    log_prob: np.ndarray  # (n_samples,)
    chains: np.ndarray  # (n_chains, n_draws, d_total) incl. sampled nuisance columns
    chain_names: list[str]
    diagnostics: dict[str, Any]
    fit: dict[str, Any]
    fit_nominal: dict[str, Any]
    log_evidence: float | None
    log_evidence_err: float | None = None
    noise: dict[str, Any] = field(default_factory=dict)
    priors: dict[str, dict[str, Any]] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    timing_s: dict[str, float] = field(default_factory=dict)
    # modes of the MAP model at every DOF, paired to the data's modes; the data's own (reference)
    # shapes expanded from the sensors to every DOF with the IIRS transformation at the MAP
    map_modes: dict[str, Any] = field(default_factory=dict)
    # observed modes left out because they pair with no model mode (pairing.UnmodelledMode dicts)
    unmodelled_modes: list[dict[str, Any]] = field(default_factory=list)

    def theta(self, which: str = "mean") -> np.ndarray:
        return np.array([getattr(self.parameters[n], which) for n in self.parameter_names])

    def summary_record(self, structure_name: str = "") -> dict[str, Any]:
        """The fields of ``shm_interfaces/msg/PosteriorSummary`` (and of its ``ParameterEstimate``
        items), by name, for the one place that converts to messages (``shm_ros.ros.convert``)."""
        d = self.diagnostics
        nan = float("nan")
        mac_mean = self.fit.get("mac_mean")
        return {
            "structure_name": structure_name,
            "sampler": str(d.get("sampler", "")),
            "likelihood": str(d.get("likelihood", "")),
            "n_windows": int(d.get("n_windows", 0)),
            "parameters": [{
                "name": n, "map": s.map, "mean": s.mean, "std": s.std,
                "ci95_low": s.ci95[0], "ci95_high": s.ci95[1],
                "rhat": float(d.get("rhat", {}).get(n, nan)),
                "ess": float(d.get("ess_bulk", {}).get(n, nan)),
            } for n, s in self.parameters.items()],
            "rhat_max": float(d.get("rhat_max", nan)),
            "ess_min": float(d.get("ess_min", nan)),
            "acceptance": float(d.get("acceptance", nan)),
            "frequency_rmse_pct": float(self.fit.get("frequency_rmse_pct", nan) or nan),
            "mac_mean": float(mac_mean) if mac_mean is not None else nan,
            "log_evidence": nan if self.log_evidence is None else float(self.log_evidence),
            "converged": bool(d.get("converged", False)),
            "warnings": list(self.warnings),
        }

    def to_dict(self) -> dict[str, Any]:
        """The ``posterior.json`` payload of docs/interfaces.md §6 (without schema/provenance)."""
        return {
            "parameters": {n: s.to_dict() for n, s in self.parameters.items()},
            "diagnostics": self.diagnostics,
            "fit": self.fit,
            "fit_nominal": self.fit_nominal,
            "log_evidence": self.log_evidence,
            "log_evidence_err": self.log_evidence_err,
            "noise": self.noise,
            "priors": self.priors,
            "warnings": self.warnings,
            "unmodelled_modes": self.unmodelled_modes,
            "timing_s": self.timing_s,
            "map_modes": self.map_modes,
        }


def summarise(samples: np.ndarray, x_map: np.ndarray, names: Sequence[str]) -> dict[str, ParameterSummary]:
    out = {}
    for i, n in enumerate(names):
        col = samples[:, i]
        lo, med, hi = np.quantile(col, [0.025, 0.5, 0.975])
        out[n] = ParameterSummary(float(x_map[i]), float(col.mean()), float(col.std(ddof=1)),
                                  (float(lo), float(hi)), float(med))
    return out


def joint_prior_for(model: AffineModel, config: UpdateConfig,
                    priors: JointPrior | Sequence[Any] | None) -> JointPrior:
    if isinstance(priors, JointPrior):
        jp = priors
    elif priors is not None:
        jp = priors_from_specs(priors)
    elif config.priors is not None:
        missing = [n for n in model.parameter_names if n not in config.priors]
        if missing:
            raise PriorError(f"no prior given for parameter(s) {missing}")
        jp = JointPrior([Prior.make(config.priors[n].get("dist", ""),
                                    {k: v for k, v in config.priors[n].items() if k != "dist"}, n)
                         for n in model.parameter_names])
    else:
        raise PriorError("update needs priors: pass them (structure 'parameters') or set config.priors")
    if jp.names != list(model.parameter_names):
        raise PriorError(f"priors are for {jp.names} but the model's parameters are "
                         f"{model.parameter_names}")
    return jp


def prior_cv(jp: JointPrior) -> float:
    """Largest coefficient of variation (std / |mean|) over the parameters' priors."""
    cv = [p.std / abs(p.mean) for p in jp.priors if np.isfinite(p.std) and p.mean != 0]
    return float(max(cv)) if cv else float("inf")


def pairing_reference(model: AffineModel, config: UpdateConfig,
                      priors: JointPrior | Sequence[Any] | None) -> tuple[np.ndarray, PairingGate]:
    """The theta at which observed modes are paired (the prior mean) and the gate, resolved from the
    config and the prior width; recordings use it to pair per-window estimates
    (``pairing.observations_for_model``) as the updating itself does."""
    jp = joint_prior_for(model, config, priors)
    gate = PairingGate.resolve(config.frequency_gate, config.mac_gate, prior_cv(jp))
    return np.array([p.mean for p in jp.priors], dtype=float), gate


def _modal_predictor(model: AffineModel, data: ModalObservations, config: UpdateConfig):
    sensors = list(data.sensor_ids) if (config.use_shapes and data.has_shapes) else []
    n_modes = config.n_modes or data.n_modes + 2
    return build_predictor(model, sensors, n_modes, config.reduction, n_required=data.n_modes)


def build_likelihood(model: AffineModel, data: Any, config: UpdateConfig, *, predictor: Any = None,
                     pairing: np.ndarray | None = None):
    """The likelihood object the config asks for (batched call (B, d_total) -> (B,)).

    Modal likelihoods: ``predictor`` (default: built for ``data``) and ``pairing``, the model mode
    of each of the data's modes (default: paired once at the nominal model, ungated; :func:`update`
    passes its gated pairing and the data restricted to the paired modes).
    """
    if config.likelihood == "time":
        from .records import RecordSet
        from .timedomain import AccelerationRecord, TimeDomainLikelihood

        if isinstance(data, RecordSet):  # several events, one joint likelihood
            return JointTimeDomainLikelihood(model, data, variance=config.variance, error_prior_shape=config.ig_shape,
                                             ar_order=config.residual_ar_order), None

        if not isinstance(data, AccelerationRecord):
            raise TypeError("likelihood 'time' needs an AccelerationRecord (input and output "
                            "accelerations), not modal data")
        lik = TimeDomainLikelihood(model, data, variance=config.variance,
                                   error_prior_shape=config.ig_shape, ar_order=config.residual_ar_order)
        lik.n_theta = model.n_parameters
        return lik, None
    if not isinstance(data, ModalObservations):
        raise TypeError(f"likelihood {config.likelihood!r} needs ModalObservations")
    if predictor is None:
        predictor = _modal_predictor(model, data, config)
    use_shapes = bool(predictor.sensor_ids) and data.has_shapes
    modal: GaussianModalLikelihood | FitnessLikelihood | ModelErrorLikelihood
    if config.likelihood == "model-error":
        modal = ModelErrorLikelihood(
            predictor, data, use_shapes=use_shapes, variance=config.variance,
            freq_prior=InverseGamma.weak(config.frequency_error_guess, config.ig_shape),
            shape_prior=InverseGamma.weak(config.shape_error_guess, config.ig_shape))
    elif config.likelihood == "gaussian":
        modal = GaussianModalLikelihood(
            predictor, data, use_shapes=use_shapes, variance=config.variance,
            freq_prior=InverseGamma.weak(config.frequency_error_guess, config.ig_shape),
            shape_prior=InverseGamma.weak(config.shape_error_guess, config.ig_shape),
            use_damping=config.use_damping,
            damping_prior=InverseGamma.weak(config.damping_error_guess, config.ig_shape))
    else:
        modal = FitnessLikelihood(predictor, data, alpha=config.alpha, beta=config.beta, k=config.k,
                                  j=config.fitness_j)
    if pairing is not None:
        set_pairing(modal, pairing)
    modal.n_theta = model.n_parameters
    return modal, predictor


def update(model: AffineModel, observations: Any, config: UpdateConfig | None = None,
           priors: JointPrior | Sequence[Any] | None = None,
           warm_start: Posterior | None = None,
           progress: Callable[[int, int], None] | None = None) -> Posterior:
    """Calibrate the model's parameters to the data; see the module docstring.

    ``observations`` is :class:`ModalObservations` (likelihood ``gaussian`` or ``fitness``) or an
    :class:`~shm_ros.core.bayes.timedomain.AccelerationRecord` (likelihood ``time``). ``priors``:
    the structure's parameter specs, a :class:`JointPrior`, or None to use ``config.priors``.
    ``warm_start``: a previous posterior of the same parameters (e.g. before new windows arrived);
    its draws join the starting points of the MAP search, so a re-run starts where the last ended.
    ``progress(steps done, steps planned)`` is called while the sampler runs.
    """
    config = config or UpdateConfig()
    config.validate()
    if config.blas_threads > 0:
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=config.blas_threads, user_api="blas"):
            return _update(model, observations, config, priors, warm_start, progress)
    return _update(model, observations, config, priors, warm_start, progress)


def _update(model: AffineModel, observations: Any, config: UpdateConfig,
            priors: JointPrior | Sequence[Any] | None, warm_start: Posterior | None = None,
            progress: Callable[[int, int], None] | None = None) -> Posterior:
    timing: dict[str, float] = {}
    t0 = time.perf_counter()
    warnings_: list[str] = []
    if isinstance(observations, ModalObservations):
        if observations.n_windows == 0:
            raise ValueError("no windows to update from")
        observations, dropped = observations.without_empty_modes()
        if dropped:
            warnings_.append(f"mode(s) {dropped} have no frequency in any window; left out")
        if observations.n_modes == 0:
            raise ValueError("the modal data hold no frequency at all")
    jp = joint_prior_for(model, config, priors)
    d = jp.dim
    full_obs = observations
    pairing: ModePairing | None = None
    pairing_at = "prior mean"
    if isinstance(observations, ModalObservations) and config.likelihood != "time":
        predictor = _modal_predictor(model, full_obs, config)
        gate = PairingGate.resolve(config.frequency_gate, config.mac_gate, prior_cv(jp))
        pairing = _gated(predictor, full_obs, np.array([p.mean for p in jp.priors]), gate)
        if pairing.observed.size == 0:
            raise ValueError("no observed mode pairs with a mode of the model at the prior mean: "
                             + " ".join(u.message(gate) for u in pairing.unmodelled))
        observations, lik = _paired_likelihood(model, full_obs, config, predictor, pairing)
    else:
        lik, predictor = build_likelihood(model, observations, config)

    def log_post(x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(x)
        lp = jp.logpdf(x[:, :d]) + lik.extra_logprior(x[:, d:])
        ok = np.isfinite(lp)
        out = np.full(x.shape[0], -np.inf)
        if ok.any():
            out[ok] = lp[ok] + safe_loglik(lik, x[ok], d)
        out[~np.isfinite(out)] = -np.inf
        return out

    rng = np.random.default_rng(config.seed)
    prior_std = np.array([p.std if np.isfinite(p.std) else 1.0 for p in jp.priors])
    starts_theta = np.vstack([np.atleast_2d([p.mean for p in jp.priors]), jp.sample(rng, 400)])
    if warm_start is not None and list(warm_start.parameter_names) == list(jp.names):
        previous = warm_start.samples[rng.permutation(len(warm_start.samples))[:200]]
        starts_theta = np.vstack([warm_start.theta("mean")[None, :], previous, starts_theta])
    for attempt in (0, 1):
        n_extra = lik.n_extra
        names = list(jp.names) + list(lik.extra_names)
        starts = np.hstack([starts_theta, lik.extra_initial(rng, starts_theta.shape[0])])
        scale = np.concatenate([prior_std, np.ones(n_extra)])
        x_map, lp_map = find_map(log_post, starts, scale, seed=config.seed)
        if attempt == 0 and isinstance(lik, TimeDomainLikelihood | JointTimeDomainLikelihood) and lik.ar_order \
                and lik.ar_coef is None:
            # time domain: the residual's AR model is estimated once, at the white-noise MAP
            lik.fix_ar(x_map[:d])
            starts_theta = np.vstack([x_map[None, :d], starts_theta])
            continue
        if pairing is None or attempt == 1 or not config.pair_at_map:
            break
        # once, at the MAP: a nominal model far from the data may have paired a mode wrongly
        again = _gated(predictor, full_obs, x_map[:d], pairing.gate)
        if again.same_as(pairing) or again.observed.size == 0:
            break
        before = pairing.describe(full_obs.mode_numbers, pairing_at)
        pairing, pairing_at = again, "MAP"
        after = pairing.describe(full_obs.mode_numbers, pairing_at)
        warnings_.append(f"pairing changed at the MAP: observed modes {before['observed_modes']} -> "
                         f"model modes {before['model_modes']} became {after['observed_modes']} -> "
                         f"{after['model_modes']}; the MAP was searched again")
        observations, lik = _paired_likelihood(model, full_obs, config, predictor, pairing)
        starts_theta = np.vstack([x_map[None, :d], starts_theta])
    unmodelled: list[dict[str, Any]] = []
    if pairing is not None:
        unmodelled = [u.to_dict() for u in pairing.unmodelled]
        warnings_ += [u.message(pairing.gate) for u in pairing.unmodelled]
    if isinstance(full_obs, ModalObservations) and full_obs.unmodelled_modes:
        # modes of a recording's windows that paired with no model mode (observations_for_model)
        unmodelled += list(full_obs.unmodelled_modes)
        warnings_ += [UnmodelledMode(**u).message(pairing.gate if pairing else PairingGate())
                      for u in full_obs.unmodelled_modes]
    cov = laplace_covariance(log_post, x_map, scale)
    timing["map_s"] = time.perf_counter() - t0
    exact_predictor = predictor
    ritz_note = _try_ritz(model, lik, predictor, x_map, cov, d, config, rng)

    t1 = time.perf_counter()
    settings = SamplerSettings(config.sampler, config.n_chains, config.n_steps, config.max_steps,
                               config.burn_in, config.rhat_target, config.ess_target, config.seed,
                               progress)
    chains: ChainResult = run_sampler(log_post, x_map, cov, settings, names)
    timing["sampling_s"] = time.perf_counter() - t1
    flat = chains.flat
    flat_lp = chains.log_prob.reshape(-1)
    best = int(np.argmax(flat_lp))
    if flat_lp[best] > lp_map:
        x_map, lp_map = flat[best].copy(), float(flat_lp[best])
    summary = summarise(flat[:, :d], x_map[:d], jp.names)

    warnings_ += list(chains.warnings)
    diag = {
        "sampler": chains.sampler,
        "rhat_max": chains.diagnostics.rhat_max,
        "ess_min": chains.diagnostics.ess_min,
        "acceptance": chains.acceptance,
        "converged": chains.converged,
        "n_chains": int(chains.chains.shape[0]),
        "n_draws": int(chains.chains.shape[1]),
        "burn_in": int(chains.burn_in),
        "n_steps": int(chains.n_steps),
        "n_evaluations": int(chains.n_evaluations),
        "rhat": dict(zip(names, map(float, chains.diagnostics.rhat), strict=True)),
        "ess_bulk": dict(zip(names, map(float, chains.diagnostics.ess_bulk), strict=True)),
        "likelihood": config.likelihood,
        "n_windows": int(getattr(observations, "n_windows", 1)),
        "predictor": ritz_note or type(predictor).__name__ if predictor is not None else "time-domain",
    }
    if pairing is not None:
        diag["pairing"] = pairing.describe(full_obs.mode_numbers, pairing_at)

    noise: dict[str, Any] = {}
    if config.likelihood in ("gaussian", "time", "model-error"):
        if config.variance == "sampled":
            for j, n in enumerate(lik.extra_names):
                v = np.exp(flat[:, d + j])
                noise[n.removeprefix("log_")] = {"mean": float(v.mean()), "std": float(v.std(ddof=1))}
        # at the MAP: variances not sampled, and the model-error scales and offsets (model-error)
        noise.update({k: {"mean": v} for k, v in lik.variance_estimates(x_map[:d]).items() if k not in noise})

    if predictor is not None:
        lik.predictor = exact_predictor  # scores and evidence with the exact model
        idx = None if pairing is None else pairing.model_index
        fit = modal_fit(predictor, observations, x_map[:d], idx)
        fit_nominal = modal_fit(predictor, observations, model.nominal_theta(), idx)
    else:
        fit = lik.fit(x_map[:d])
        fit_nominal = lik.fit(model.nominal_theta())

    map_modes = _map_modes(model, observations, x_map[:d], fit) if predictor is not None else {}

    log_z = log_z_err = None
    if config.evidence:
        t2 = time.perf_counter()
        marginal = lik if getattr(lik, "variance", "marginal") == "marginal" else \
            _marginal_twin(model, observations, config, predictor,
                           None if pairing is None else pairing.model_index)
        saved = getattr(marginal, "predictor", None)
        note = _one_point_predictor(model, marginal, x_map[:d], cov[:d, :d])
        try:
            ev = nested_evidence(lambda x: safe_loglik(marginal, x, d), jp, n_live=config.n_live,
                                 seed=config.seed)
        finally:
            if saved is not None:
                marginal.predictor = saved
        log_z, log_z_err = ev.log_evidence, ev.log_evidence_err
        timing["evidence_s"] = time.perf_counter() - t2
        diag["evidence_method"] = ev.method + (f", {note}" if note else "")
    timing["total_s"] = time.perf_counter() - t0
    return Posterior(
        parameter_names=list(jp.names), parameters=summary, samples=flat[:, :d].copy(),
        log_prob=flat_lp, chains=chains.chains, chain_names=names, diagnostics=diag, fit=fit,
        fit_nominal=fit_nominal, log_evidence=log_z, log_evidence_err=log_z_err, noise=noise,
        priors={p.name: p.describe() for p in jp.priors}, warnings=warnings_, timing_s=timing,
        map_modes=map_modes, unmodelled_modes=unmodelled)


def _gated(predictor: Any, obs: ModalObservations, theta: np.ndarray, gate: PairingGate) -> ModePairing:
    """The data's modes (mean frequency, mean shape) paired with the model's at one theta."""
    phi = obs.reference_shapes() if (predictor.sensor_ids and obs.has_shapes) else None
    return pair_with_model(predictor, obs.mean_frequencies(), phi, theta, gate, obs.mode_numbers)


def _paired_likelihood(model: AffineModel, obs: ModalObservations, config: UpdateConfig, predictor: Any,
                       pairing: ModePairing) -> tuple[ModalObservations, Any]:
    """The data restricted to the paired modes and the likelihood with that fixed pairing."""
    kept = select_modes(obs, pairing.observed)
    lik, _ = build_likelihood(model, kept, config, predictor=predictor, pairing=pairing.model_index)
    return kept, lik


def _map_modes(model: AffineModel, obs: ModalObservations, theta: np.ndarray, fit: dict) -> dict:
    """MAP model modes at all DOFs (paired as in ``fit``) and the data's shapes expanded by IIRS."""
    idx = [m["model_mode_index"] - 1 for m in fit["modes"]]
    sol = model.modes(theta, max(idx) + 1)
    out: dict[str, Any] = {
        "mode_numbers": list(obs.mode_numbers),
        "dof_labels": list(model.dof_labels),
        "frequencies_hz": [float(sol.frequencies_hz[i]) for i in idx],
        "model_shapes": [unit_max(sol.shapes[:, i]).tolist() for i in idx],
        "observed_shapes_expanded": None,
    }
    ref = obs.reference_shapes() if obs.has_shapes else None
    if ref is not None and np.all(np.isfinite(ref)):
        try:
            from shm_ros.core.models.reduction import expand_sensor_shapes

            full = expand_sensor_shapes(model, obs.sensor_ids, ref.T, theta)
            out["observed_shapes_expanded"] = [unit_max(full[:, k]).tolist() for k in range(full.shape[1])]
        except (KeyError, ValueError, np.linalg.LinAlgError):
            pass  # sensors not on DOFs (girder read by shape functions): no expansion
    return out


def safe_loglik(lik: Any, x: np.ndarray, d: int) -> np.ndarray:
    """Likelihood of a batch with non-physical rows set to -inf instead of failing the batch.

    Every parameter is a multiplicative factor on a positive quantity (stiffness, mass, modulus,
    damping), so theta <= 0 has zero likelihood; a batch whose matrices are singular for some row
    (numpy's stacked solvers raise for the whole stack) is evaluated row by row.
    """
    x = np.atleast_2d(x)
    out = np.full(x.shape[0], -np.inf)
    ok = np.all(x[:, :d] > 0, axis=1)
    if not ok.any():
        return out
    with np.errstate(all="ignore"):
        try:
            out[ok] = lik(x[ok])
        except np.linalg.LinAlgError:
            for i in np.flatnonzero(ok):
                try:
                    out[i] = lik(x[i:i + 1])[0]
                except np.linalg.LinAlgError:
                    out[i] = -np.inf
    out[~np.isfinite(out)] = -np.inf
    return out


def _modes_used(lik: Any) -> int:
    """How many of the model's lowest modes the likelihood reads (its pairing may skip some)."""
    st = lik.stats
    return int(st.model_index.max()) + 1 if st.model_index is not None and st.model_index.size else len(st.f_ref)


def _try_ritz(model: AffineModel, lik: Any, predictor: Any, x_map: np.ndarray, cov: np.ndarray,
              d: int, config: UpdateConfig, rng: np.random.Generator) -> str | None:
    """Swap in a Rayleigh-Ritz predictor for sampling when the model is large and the projection
    is accurate to 1e-7 (frequencies, MAC) over a wide region around the MAP (6 Laplace standard
    deviations); otherwise keep the exact predictor. Returns a note for the diagnostics or None."""
    from .forward import RitzModalPredictor

    if not config.ritz or predictor is None or model.n_dof < 40:
        return None
    sd = np.sqrt(np.clip(np.diag(cov)[:d], 0, None))
    step = np.maximum(3.0 * sd, 1e-3 * np.abs(x_map[:d]))
    ritz = RitzModalPredictor(model, predictor.sensor_ids, predictor.n_modes, x_map[:d], step)
    L = np.linalg.cholesky(cov[:d, :d] + 1e-300 * np.eye(d))
    check = x_map[:d] + 6.0 * rng.standard_normal((64, d)) @ L.T / np.sqrt(d)
    check = np.vstack([x_map[:d], check[np.all(check > 0, axis=1)]])
    n_req = _modes_used(lik)
    ferr, macerr = ritz.max_error(predictor, check, min(n_req + 1, predictor.n_modes))
    if ferr < 1e-7 and macerr < 1e-7:
        lik.predictor = ritz
        return f"ritz({ritz.basis_size} of {model.n_dof} DOF; max freq error {ferr:.1e})"
    return None


def _one_point_predictor(model: AffineModel, lik: Any, theta: np.ndarray, cov: np.ndarray) -> str | None:
    """Nested sampling evaluates one point at a time, where the IIRS iteration's per-call cost
    dominates; the full model gives the same modes (checked: 1e-6 in frequency, MAC, at 32 points
    around the MAP) and is far cheaper per point for small models, so it is used for the evidence."""
    from .forward import FullModalPredictor, ReducedModalPredictor

    pred = getattr(lik, "predictor", None)
    if not isinstance(pred, ReducedModalPredictor) or model.n_dof > 40:
        return None
    full = FullModalPredictor(model, pred.sensor_ids, pred.n_modes)
    rng = np.random.default_rng(0)
    L = np.linalg.cholesky(cov + 1e-300 * np.eye(theta.size))
    pts = np.vstack([theta, theta + 6.0 * rng.standard_normal((31, theta.size)) @ L.T])
    pts = pts[np.all(pts > 0, axis=1)]
    f_r, p_r = pred(pts)
    f_f, p_f = full(pts)
    n = min(_modes_used(lik), pred.n_modes)
    ok = np.max(np.abs(f_r[:, :n] / f_f[:, :n] - 1)) < 1e-6
    if p_r.shape[1]:
        ok &= np.max(1 - mac(np.swapaxes(p_r[:, :, :n], 1, 2), np.swapaxes(p_f[:, :, :n], 1, 2))) < 1e-6
    if not ok:
        return None
    lik.predictor = full
    return "full model (equal to the IIRS model to 1e-6, cheaper per point)"


def _marginal_twin(model: AffineModel, data: Any, config: UpdateConfig, predictor: Any = None,
                   pairing: np.ndarray | None = None):
    """The same likelihood with the variances integrated out (the evidence needs only theta)."""
    twin = UpdateConfig(**{**asdict(config), "variance": "marginal"})
    if pairing is None:
        lik, _ = build_likelihood(model, data, twin)
    else:
        lik, _ = build_likelihood(model, data, twin, predictor=predictor, pairing=pairing)
    return lik


def priors_from_structure(spec: Any) -> list[Any]:
    """Parameter specs of a ``StructureSpec`` (its ``parameters`` list) for :func:`update`."""
    params = getattr(spec, "parameters", None)
    if not params:
        raise PriorError(f"structure '{getattr(spec, 'name', '?')}' lists no 'parameters' to update")
    return list(params)


def config_from_mapping(values: Mapping[str, Any]) -> UpdateConfig:
    """An UpdateConfig from a plain mapping (node parameters, YAML); unknown keys are an error."""
    known = set(UpdateConfig.__dataclass_fields__)
    bad = sorted(set(values) - known)
    if bad:
        raise ValueError(f"unknown update setting(s) {bad}; known: {sorted(known)}")
    cfg = UpdateConfig(**dict(values))
    cfg.validate()
    return cfg


__all__ = ["UpdateConfig", "Posterior", "ParameterSummary", "update", "summarise",
           "config_from_mapping", "priors_from_structure", "pairing_reference"]
