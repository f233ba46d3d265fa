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
from shm_ros.core.observations import ModalObservations
from shm_ros.core.priors import JointPrior, Prior, PriorError, priors_from_specs

from .evidence import nested_evidence
from .fit import modal_fit
from .forward import build_predictor
from .likelihood_kinds.base import (
    LIKELIHOODS,
    Likelihood,
    LikelihoodInputs,
    LikelihoodKind,
    LikelihoodName,
    likelihood_kind,
)
from .likelihoods import FitnessJ
from .pairing import DEFAULT_MAC_GATE, ModePairing, PairingGate, UnmodelledMode, pair_with_model, select_modes
from .sampler_kinds.base import SAMPLERS, SamplerName, sampler_kind
from .samplers import ChainResult, SamplerSettings, find_map, laplace_covariance


class Variance(enum.StrEnum):  # prediction-error variances of the Gaussian likelihood
    MARGINAL = "marginal"  # integrated out
    SAMPLED = "sampled"


class Reduction(enum.StrEnum):
    AUTO = "auto"  # IIRS when sensors are fewer than DOFs and it is exact and cheaper
    IIRS = "iirs"
    NONE = "none"


@dataclass
class UpdateConfig:
    """Settings of one updating run (every field has a default; all are plain data)."""

    likelihood: str = option(LikelihoodName.MODEL_ERROR.value, "model-error: modal data with a systematic "
                             "model error shared by all windows (docs/updating.md); gaussian: windows "
                             "independent; the bridge paper's fitness exp(-J/2k^2); or time: "
                             "accelerations under the measured input", choices=LikelihoodName)
    sampler: str = option(SamplerName.EMCEE.value, "emcee ensemble or adaptive Metropolis-Hastings",
                          choices=SamplerName)
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
    variance_per_event: bool = option(False, "time likelihood over several events: each event its own "
                                      "error variance per channel (a model error relative to the response "
                                      "weighs every event alike; else one variance per channel, which the "
                                      "strongest event's residuals dominate); needs variance: marginal")
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
        check_choice("update", "likelihood", self.likelihood, LIKELIHOODS.names())  # built in and added
        check_choice("update", "sampler", self.sampler, SAMPLERS.names())
        check_choice("update", "reduction", self.reduction, Reduction)
        check_choice("update", "variance", self.variance, Variance)
        check_choice("update", "fitness_j", self.fitness_j, FitnessJ)
        if self.use_damping and not likelihood_kind(self.likelihood).uses_damping:
            with_damping = [k.name for k in LIKELIHOODS if k.uses_damping]
            raise ValueError(f"update: use_damping needs a likelihood damping ratios enter ({with_damping}), "
                             f"got likelihood {self.likelihood!r}")
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
                     pairing: np.ndarray | None = None) -> tuple[Likelihood, Any]:
    """The likelihood the config names (batched call (B, d_total) -> (B,)) and its predictor.

    Modal likelihoods: ``predictor`` (default: built for ``data``) and ``pairing``, the model mode
    of each of the data's modes (default: paired once at the nominal model, ungated; :func:`update`
    passes its gated pairing and the data restricted to the paired modes). Others: predictor None.
    """
    kind = likelihood_kind(config.likelihood)
    if not kind.modal:
        return kind.build(LikelihoodInputs(model, data, config)), None
    if not isinstance(data, ModalObservations):
        raise TypeError(f"likelihood {config.likelihood!r} needs ModalObservations")
    if predictor is None:
        predictor = _modal_predictor(model, data, config)
    return kind.build(LikelihoodInputs(model, data, config, predictor, pairing)), predictor


def update(model: AffineModel, observations: Any, config: UpdateConfig | None = None,
           priors: JointPrior | Sequence[Any] | None = None,
           warm_start: Posterior | None = None,
           progress: Callable[[int, int], None] | None = None) -> Posterior:
    """Calibrate the model's parameters to the data; see the module docstring.

    ``observations`` is :class:`ModalObservations` (the modal likelihoods) or an
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
    """The steps of one run, each adding to the :class:`_Run`: pair, MAP, re-pair, sample, evidence,
    summarise."""
    run = _start(model, observations, config, joint_prior_for(model, config, priors), progress)
    _pair(run)
    _search_map(run, warm_start)
    if run.lik.prepare_at_map(run.x_map[:run.d]) or _pair_again_at_map(run):
        _search_map(run, None)
    _after_map(run)
    _sample(run)
    _evidence(run)
    return _summarise(run)


@dataclass
class _Run:
    """One updating run: its inputs, and what each step of :func:`_update` adds."""

    model: AffineModel
    config: UpdateConfig
    jp: JointPrior
    kind: LikelihoodKind
    full_obs: Any  # the data as given (modal data without empty modes)
    progress: Callable[[int, int], None] | None
    rng: np.random.Generator
    t0: float
    observations: Any = None  # the data the likelihood reads (modal: the paired modes only)
    predictor: Any = None  # the exact predictor of the model's modes (modal likelihoods)
    pairing: ModePairing | None = None
    pairing_at: str = "prior mean"
    lik: Any = None  # the likelihood with the exact predictor (a ``Likelihood``)
    starts_theta: np.ndarray | None = None
    x_map: np.ndarray = field(default_factory=lambda: np.zeros(0))
    lp_map: float = -np.inf
    scale: np.ndarray = field(default_factory=lambda: np.zeros(0))
    names: list[str] = field(default_factory=list)
    cov: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    chains: ChainResult | None = None
    predictor_note: str | None = None
    log_z: float | None = None
    log_z_err: float | None = None
    evidence_method: str | None = None
    unmodelled: list[dict[str, Any]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    timing: dict[str, float] = field(default_factory=dict)

    @property
    def d(self) -> int:
        return self.jp.dim

    def paired_likelihood(self, predictor: Any, config: UpdateConfig | None = None) -> Likelihood:
        """The run's likelihood built again with another predictor (or config), same pairing."""
        idx = None if self.pairing is None else self.pairing.model_index
        return self.kind.build(LikelihoodInputs(self.model, self.observations, config or self.config,
                                                predictor, idx))


def _start(model: AffineModel, observations: Any, config: UpdateConfig, jp: JointPrior,
           progress: Callable[[int, int], None] | None) -> _Run:
    """The run object; modal data lose modes without any frequency."""
    run = _Run(model, config, jp, likelihood_kind(config.likelihood), observations, progress,
               np.random.default_rng(config.seed), time.perf_counter())
    if isinstance(observations, ModalObservations):
        if observations.n_windows == 0:
            raise ValueError("no windows to update from")
        run.full_obs, dropped = observations.without_empty_modes()
        if dropped:
            run.warnings.append(f"mode(s) {dropped} have no frequency in any window; left out")
        if run.full_obs.n_modes == 0:
            raise ValueError("the modal data hold no frequency at all")
    run.observations = run.full_obs
    return run


def _pair(run: _Run) -> None:
    """Modal likelihoods: pair the data's modes with the model's at the prior mean, behind the gate,
    and build the likelihood on the paired modes; others: build the likelihood on the data."""
    if not run.kind.modal:
        run.lik = run.kind.build(LikelihoodInputs(run.model, run.full_obs, run.config))
        return
    if not isinstance(run.full_obs, ModalObservations):
        raise TypeError(f"likelihood {run.config.likelihood!r} needs ModalObservations")
    run.predictor = _modal_predictor(run.model, run.full_obs, run.config)
    gate = PairingGate.resolve(run.config.frequency_gate, run.config.mac_gate, prior_cv(run.jp))
    run.pairing = _gated(run.predictor, run.full_obs, np.array([p.mean for p in run.jp.priors]), gate)
    if run.pairing.observed.size == 0:
        raise ValueError("no observed mode pairs with a mode of the model at the prior mean: "
                         + " ".join(u.message(gate) for u in run.pairing.unmodelled))
    _use_pairing(run)


def _use_pairing(run: _Run) -> None:
    assert run.pairing is not None
    run.observations = select_modes(run.full_obs, run.pairing.observed)
    run.lik = run.paired_likelihood(run.predictor)


def _log_posterior(jp: JointPrior, lik: Likelihood) -> Callable[[np.ndarray], np.ndarray]:
    """Batched log-posterior of (theta, nuisance columns): prior + likelihood, -inf where either is."""
    d = jp.dim

    def log_post(x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(x)
        lp = jp.logpdf(x[:, :d]) + lik.extra_logprior(x[:, d:])
        ok = np.isfinite(lp)
        out = np.full(x.shape[0], -np.inf)
        if ok.any():
            out[ok] = lp[ok] + safe_loglik(lik, x[ok], d)
        out[~np.isfinite(out)] = -np.inf
        return out

    return log_post


def _search_map(run: _Run, warm_start: Posterior | None) -> None:
    """The MAP from the prior mean, prior draws, a previous posterior's draws and the last MAP."""
    jp, d = run.jp, run.d
    if run.starts_theta is None:
        run.starts_theta = np.vstack([np.atleast_2d([p.mean for p in jp.priors]), jp.sample(run.rng, 400)])
        if warm_start is not None and list(warm_start.parameter_names) == list(jp.names):
            previous = warm_start.samples[run.rng.permutation(len(warm_start.samples))[:200]]
            run.starts_theta = np.vstack([warm_start.theta("mean")[None, :], previous, run.starts_theta])
    else:
        run.starts_theta = np.vstack([run.x_map[None, :d], run.starts_theta])
    lik = run.lik
    run.names = list(jp.names) + list(lik.extra_names)
    starts = np.hstack([run.starts_theta, lik.extra_initial(run.rng, run.starts_theta.shape[0])])
    prior_std = np.array([p.std if np.isfinite(p.std) else 1.0 for p in jp.priors])
    run.scale = np.concatenate([prior_std, np.ones(lik.n_extra)])
    run.x_map, run.lp_map = find_map(_log_posterior(jp, lik), starts, run.scale, seed=run.config.seed)


def _pair_again_at_map(run: _Run) -> bool:
    """Once, at the MAP: a nominal model far from the data may have paired a mode wrongly. True when
    the pairing changed (the likelihood is then rebuilt and the MAP searched again)."""
    if run.pairing is None or not run.config.pair_at_map:
        return False
    again = _gated(run.predictor, run.full_obs, run.x_map[:run.d], run.pairing.gate)
    if again.same_as(run.pairing) or again.observed.size == 0:
        return False
    before = run.pairing.describe(run.full_obs.mode_numbers, run.pairing_at)
    run.pairing, run.pairing_at = again, "MAP"
    after = run.pairing.describe(run.full_obs.mode_numbers, run.pairing_at)
    run.warnings.append(f"pairing changed at the MAP: observed modes {before['observed_modes']} -> "
                        f"model modes {before['model_modes']} became {after['observed_modes']} -> "
                        f"{after['model_modes']}; the MAP was searched again")
    _use_pairing(run)
    return True


def _after_map(run: _Run) -> None:
    """The modes left out by the pairing (reported) and the Laplace covariance at the MAP."""
    gate = run.pairing.gate if run.pairing is not None else PairingGate()
    if run.pairing is not None:
        run.unmodelled = [u.to_dict() for u in run.pairing.unmodelled]
        run.warnings += [u.message(gate) for u in run.pairing.unmodelled]
    if isinstance(run.full_obs, ModalObservations) and run.full_obs.unmodelled_modes:
        # modes of a recording's windows that paired with no model mode (observations_for_model)
        run.unmodelled += list(run.full_obs.unmodelled_modes)
        run.warnings += [UnmodelledMode(**u).message(gate) for u in run.full_obs.unmodelled_modes]
    run.cov = laplace_covariance(_log_posterior(run.jp, run.lik), run.x_map, run.scale)
    run.timing["map_s"] = time.perf_counter() - run.t0


def _sample(run: _Run) -> None:
    """MCMC from the MAP with the registered sampler (with a Rayleigh-Ritz predictor when it is exact
    enough); a better point found by the chains becomes the MAP."""
    lik = run.lik
    ritz = _ritz_predictor(run)
    if ritz is not None:
        lik = run.paired_likelihood(ritz[0])
        run.predictor_note = ritz[1]
    t1 = time.perf_counter()
    c = run.config
    settings = SamplerSettings(c.sampler, c.n_chains, c.n_steps, c.max_steps, c.burn_in, c.rhat_target,
                               c.ess_target, c.seed, run.progress)
    run.chains = sampler_kind(c.sampler).run(_log_posterior(run.jp, lik), run.x_map, run.cov, settings,
                                             run.names)
    run.timing["sampling_s"] = time.perf_counter() - t1
    flat_lp = run.chains.log_prob.reshape(-1)
    best = int(np.argmax(flat_lp))
    if flat_lp[best] > run.lp_map:
        run.x_map, run.lp_map = run.chains.flat[best].copy(), float(flat_lp[best])
    run.warnings += list(run.chains.warnings)


def _evidence(run: _Run) -> None:
    """Log evidence by nested sampling over theta, the variances integrated out."""
    if not run.config.evidence:
        return
    t2 = time.perf_counter()
    d = run.d
    cheaper = _one_point_predictor(run)
    marginal = run.lik
    if cheaper is not None or run.config.variance != Variance.MARGINAL.value:
        twin = UpdateConfig(**{**asdict(run.config), "variance": Variance.MARGINAL.value})
        predictor = cheaper[0] if cheaper is not None else run.predictor
        marginal = run.paired_likelihood(predictor, twin) if run.kind.modal else \
            run.kind.build(LikelihoodInputs(run.model, run.observations, twin))
    ev = nested_evidence(lambda x: safe_loglik(marginal, x, d), run.jp, n_live=run.config.n_live,
                         seed=run.config.seed)
    run.log_z, run.log_z_err = ev.log_evidence, ev.log_evidence_err
    run.timing["evidence_s"] = time.perf_counter() - t2
    run.evidence_method = ev.method + (f", {cheaper[1]}" if cheaper is not None else "")


def _summarise(run: _Run) -> Posterior:
    """The posterior: parameter summaries, diagnostics, noise, fit at the MAP and nominal, MAP modes."""
    assert run.chains is not None
    d, jp, chains = run.d, run.jp, run.chains
    flat = chains.flat
    theta_map = run.x_map[:d]
    if run.kind.modal:
        idx = None if run.pairing is None else run.pairing.model_index
        fit = modal_fit(run.predictor, run.observations, theta_map, idx)
        fit_nominal = modal_fit(run.predictor, run.observations, run.model.nominal_theta(), idx)
        map_modes = _map_modes(run.model, run.observations, theta_map, fit)
    else:
        fit, fit_nominal, map_modes = run.lik.fit(theta_map), run.lik.fit(run.model.nominal_theta()), {}
    run.timing["total_s"] = time.perf_counter() - run.t0
    return Posterior(
        parameter_names=list(jp.names), parameters=summarise(flat[:, :d], theta_map, jp.names),
        samples=flat[:, :d].copy(), log_prob=chains.log_prob.reshape(-1), chains=chains.chains,
        chain_names=run.names, diagnostics=_diagnostics(run), fit=fit, fit_nominal=fit_nominal,
        log_evidence=run.log_z, log_evidence_err=run.log_z_err, noise=_noise(run),
        priors={p.name: p.describe() for p in jp.priors}, warnings=run.warnings, timing_s=run.timing,
        map_modes=map_modes, unmodelled_modes=run.unmodelled)


def _diagnostics(run: _Run) -> dict[str, Any]:
    ch = run.chains
    assert ch is not None
    diag = {
        "sampler": ch.sampler, "rhat_max": ch.diagnostics.rhat_max, "ess_min": ch.diagnostics.ess_min,
        "acceptance": ch.acceptance, "converged": ch.converged,
        "n_chains": int(ch.chains.shape[0]), "n_draws": int(ch.chains.shape[1]),
        "burn_in": int(ch.burn_in), "n_steps": int(ch.n_steps), "n_evaluations": int(ch.n_evaluations),
        "rhat": dict(zip(run.names, map(float, ch.diagnostics.rhat), strict=True)),
        "ess_bulk": dict(zip(run.names, map(float, ch.diagnostics.ess_bulk), strict=True)),
        "likelihood": run.config.likelihood,
        "n_windows": int(getattr(run.observations, "n_windows", 1)),
        "predictor": (run.predictor_note or type(run.predictor).__name__) if run.predictor is not None
        else "time-domain",
    }
    if run.pairing is not None:
        diag["pairing"] = run.pairing.describe(run.full_obs.mode_numbers, run.pairing_at)
    if run.evidence_method is not None:
        diag["evidence_method"] = run.evidence_method
    return diag


def _noise(run: _Run) -> dict[str, Any]:
    """Sampled variances (posterior mean and std), then the likelihood's own estimates at the MAP."""
    assert run.chains is not None
    flat, d = run.chains.flat, run.d
    noise: dict[str, Any] = {}
    for j, n in enumerate(run.lik.extra_names if run.config.variance == Variance.SAMPLED.value else []):
        v = np.exp(flat[:, d + j])
        noise[n.removeprefix("log_")] = {"mean": float(v.mean()), "std": float(v.std(ddof=1))}
    estimates = run.lik.variance_estimates(run.x_map[:d])
    noise.update({k: {"mean": v} for k, v in estimates.items() if k not in noise})
    return noise


def _gated(predictor: Any, obs: ModalObservations, theta: np.ndarray, gate: PairingGate) -> ModePairing:
    """The data's modes (mean frequency, mean shape) paired with the model's at one theta."""
    phi = obs.reference_shapes() if (predictor.sensor_ids and obs.has_shapes) else None
    return pair_with_model(predictor, obs.mean_frequencies(), phi, theta, gate, obs.mode_numbers)


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


def _modes_used(run: _Run) -> int:
    """How many of the model's lowest modes the likelihood reads (its pairing may skip some)."""
    assert run.pairing is not None
    return int(run.pairing.model_index.max()) + 1


def _ritz_predictor(run: _Run) -> tuple[Any, str] | None:
    """A Rayleigh-Ritz predictor for sampling, with a note for the diagnostics, when the model is
    large and the projection is accurate to 1e-7 (frequencies, MAC) over a wide region around the
    MAP (6 Laplace standard deviations); None keeps the exact predictor."""
    from .forward import RitzModalPredictor

    model, predictor, d, x_map, cov = run.model, run.predictor, run.d, run.x_map, run.cov
    if not run.config.ritz or predictor is None or model.n_dof < 40:
        return None
    sd = np.sqrt(np.clip(np.diag(cov)[:d], 0, None))
    step = np.maximum(3.0 * sd, 1e-3 * np.abs(x_map[:d]))
    ritz = RitzModalPredictor(model, predictor.sensor_ids, predictor.n_modes, x_map[:d], step)
    L = np.linalg.cholesky(cov[:d, :d] + 1e-300 * np.eye(d))
    check = x_map[:d] + 6.0 * run.rng.standard_normal((64, d)) @ L.T / np.sqrt(d)
    check = np.vstack([x_map[:d], check[np.all(check > 0, axis=1)]])
    ferr, macerr = ritz.max_error(predictor, check, min(_modes_used(run) + 1, predictor.n_modes))
    if ferr < 1e-7 and macerr < 1e-7:
        return ritz, f"ritz({ritz.basis_size} of {model.n_dof} DOF; max freq error {ferr:.1e})"
    return None


def _one_point_predictor(run: _Run) -> tuple[Any, str] | None:
    """Nested sampling evaluates one point at a time, where the IIRS iteration's per-call cost
    dominates; the full model gives the same modes (checked: 1e-6 in frequency, MAC, at 32 points
    around the MAP) and is far cheaper per point for small models, so it is used for the evidence."""
    from .forward import FullModalPredictor, ReducedModalPredictor

    pred, model, theta = run.predictor, run.model, run.x_map[:run.d]
    if not isinstance(pred, ReducedModalPredictor) or model.n_dof > 40:
        return None
    full = FullModalPredictor(model, pred.sensor_ids, pred.n_modes)
    rng = np.random.default_rng(0)
    L = np.linalg.cholesky(run.cov[:run.d, :run.d] + 1e-300 * np.eye(theta.size))
    pts = np.vstack([theta, theta + 6.0 * rng.standard_normal((31, theta.size)) @ L.T])
    pts = pts[np.all(pts > 0, axis=1)]
    f_r, p_r = pred(pts)
    f_f, p_f = full(pts)
    n = min(_modes_used(run), pred.n_modes)
    ok = np.max(np.abs(f_r[:, :n] / f_f[:, :n] - 1)) < 1e-6
    if p_r.shape[1]:
        ok &= np.max(1 - mac(np.swapaxes(p_r[:, :, :n], 1, 2), np.swapaxes(p_f[:, :, :n], 1, 2))) < 1e-6
    if not ok:
        return None
    return full, "full model (equal to the IIRS model to 1e-6, cheaper per point)"


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
