"""The bridge paper's hyperparameter study: priors x fitness weights -> per-mode RMSE and MAC.

For each configuration the structure is updated with the fitness likelihood
``exp(-J / (2 k^2))`` and scored at the posterior mean:

* the prior family is swept with alpha = beta = 0.5: normal, Weibull and lognormal, each with the
  mean and standard deviation of the structure file's prior (moment matching), and
* the weights (alpha, beta) in {(1, 0), (0.8, 0.2), (0.2, 0.8), (0, 1)} with the normal prior.

Per-mode RMSE = root mean square over the windows of the relative frequency error
(f_obs - f_model) / f_obs; per-mode MAC = mean over windows of MAC(observed shape, model shape),
with the updating's own pairing (modes it left out as unmodelled are not scored).

J is averaged over the windows by default here (``fitness_j="averaged"``): summed over many windows
(the bridge paper had 1,152) J outweighs any prior and the prior family no longer matters, while
the paper's Table 1 shows that it does (docs/updating.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from shm_ros.core.models.base import AffineModel
from shm_ros.core.observations import ModalObservations
from shm_ros.core.priors import JointPrior, Prior, weibull_matching

from .fit import modal_fit
from .forward import build_predictor
from .likelihoods import FitnessJ
from .pairing import select_modes
from .update import UpdateConfig, update

PRIOR_FAMILIES = ("normal", "weibull", "lognormal")
WEIGHTS = ((1.0, 0.0), (0.8, 0.2), (0.2, 0.8), (0.0, 1.0))


@dataclass
class StudyRow:
    group: str  # "prior" | "weights"
    configuration: str
    prior: str
    alpha: float
    beta: float
    rmse: list[float]  # per mode, relative (fraction)
    mac: list[float | None]  # per mode
    parameters: dict[str, float]  # posterior means
    parameter_std: dict[str, float]
    diagnostics: dict[str, Any]
    fitness_j: str = FitnessJ.AVERAGED.value
    modes: list[int] | None = None  # the scored (paired) mode numbers

    def to_dict(self) -> dict[str, Any]:
        return {"group": self.group, "configuration": self.configuration, "prior": self.prior,
                "alpha": self.alpha, "beta": self.beta, "fitness_j": self.fitness_j,
                "modes": self.modes, "rmse": self.rmse, "mac": self.mac,
                "parameters": self.parameters, "parameter_std": self.parameter_std,
                "diagnostics": self.diagnostics}


def family_prior(base: JointPrior, family: str) -> JointPrior:
    """The same mean and standard deviation per parameter, in another family."""
    out = []
    for p in base.priors:
        m, s = p.mean, p.std
        if family == "normal":
            out.append(Prior.make("normal", {"mean": m, "std": s}, p.name))
        elif family == "lognormal":
            out.append(Prior.make("lognormal", {"mean": m, "std": s}, p.name))
        elif family == "weibull":
            out.append(Prior.make("weibull", weibull_matching(m, s), p.name))
        else:
            raise ValueError(f"unknown prior family {family!r} (use {PRIOR_FAMILIES})")
    return JointPrior(out)


def bridge_study(model: AffineModel, observations: ModalObservations, base_prior: JointPrior,
                 config: UpdateConfig | None = None, families: Sequence[str] = PRIOR_FAMILIES,
                 weights: Sequence[tuple[float, float]] = WEIGHTS,
                 fitness_j: str = FitnessJ.AVERAGED.value) -> list[StudyRow]:
    """The sweep; every run uses ``config`` with the fitness likelihood, J ``fitness_j``."""
    config = config or UpdateConfig(sampler="mh")
    cfg = replace(config, likelihood="fitness", evidence=False, fitness_j=fitness_j)
    runs: list[tuple[str, str, str, float, float]] = []
    for fam in families:
        runs.append(("prior", fam, fam, 0.5, 0.5))
    for a, b in weights:
        runs.append(("weights", f"alpha={a:g}, beta={b:g}", "normal", a, b))
    sensors = list(observations.sensor_ids) if observations.has_shapes else []
    pred = build_predictor(model, sensors, cfg.n_modes or observations.n_modes + 2, cfg.reduction,
                           n_required=observations.n_modes)
    rows = []
    for group, label, fam, a, b in runs:
        if b > 0 and not observations.has_shapes:
            raise ValueError("the study's shape-weighted configurations need mode shapes in the data")
        post = update(model, observations, replace(cfg, alpha=a, beta=b),
                      priors=family_prior(base_prior, fam))
        paired = post.diagnostics["pairing"]
        keep = np.array([observations.mode_numbers.index(m) for m in paired["observed_modes"]], dtype=int)
        idx = np.array([j - 1 for j in paired["model_modes"]], dtype=int)
        fit = modal_fit(pred, select_modes(observations, keep), post.theta("mean"), idx)
        rows.append(StudyRow(
            group, label, fam, a, b,
            rmse=[m["frequency_rmse"] for m in fit["modes"]],
            mac=[m["mac"] for m in fit["modes"]],
            parameters={n: s.mean for n, s in post.parameters.items()},
            parameter_std={n: s.std for n, s in post.parameters.items()},
            diagnostics={k: post.diagnostics[k] for k in ("sampler", "rhat_max", "ess_min",
                                                          "acceptance", "converged")},
            fitness_j=fitness_j, modes=list(paired["observed_modes"])))
    return rows


def format_table(rows: list[StudyRow], mode_numbers: Sequence[int]) -> str:
    """Plain-text table in the layout of the bridge paper's Table 1."""
    def ordinal(k: int) -> str:
        return f"{k}{'th' if 10 <= k % 100 <= 20 else {1: 'st', 2: 'nd', 3: 'rd'}.get(k % 10, 'th')}"

    heads = [ordinal(k) for k in mode_numbers]
    w_set, w_cfg = 28, 22
    line1 = f"{'Hyperparameter set':<{w_set}}{'Configuration':<{w_cfg}}" + \
        f"{'RMSE':<{8 * len(heads)}}" + "MAC"
    line2 = " " * (w_set + w_cfg) + "".join(f"{h:>8}" for h in heads) * 2
    out = [line1, line2, "-" * len(line2)]
    for r in rows:
        group = "Prior (alpha=beta=0.5)" if r.group == "prior" else "Weights (normal prior)"
        cells = "".join(f"{v:8.3f}" for v in r.rmse) + "".join(
            f"{v:8.3f}" if v is not None else f"{'-':>8}" for v in r.mac)
        out.append(f"{group[:w_set - 1]:<{w_set}}{r.configuration[:w_cfg - 1]:<{w_cfg}}{cells}")
    return "\n".join(out)


__all__ = ["StudyRow", "bridge_study", "format_table", "family_prior", "PRIOR_FAMILIES", "WEIGHTS"]
