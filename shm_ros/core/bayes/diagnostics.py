"""Convergence diagnostics of MCMC output through ArviZ (rank-normalised R-hat, bulk/tail ESS)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np


def _arviz():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        import arviz as az
    return az


@dataclass
class ChainDiagnostics:
    """Per-parameter R-hat and effective sample sizes, and the worst of each."""

    names: list[str]
    rhat: np.ndarray
    ess_bulk: np.ndarray
    ess_tail: np.ndarray
    acceptance: float = float("nan")
    notes: list[str] = field(default_factory=list)

    @property
    def rhat_max(self) -> float:
        return float(np.nanmax(self.rhat)) if self.rhat.size else float("nan")

    @property
    def ess_min(self) -> float:
        return float(np.nanmin(np.minimum(self.ess_bulk, self.ess_tail))) if self.ess_bulk.size else 0.0

    def meets(self, rhat_target: float, ess_target: float) -> bool:
        return bool(self.rhat_max < rhat_target and self.ess_min >= ess_target)


def chain_diagnostics(chains: np.ndarray, names: list[str] | None = None) -> ChainDiagnostics:
    """Diagnostics of ``chains`` (n_chains, n_draws, d) with ArviZ."""
    az = _arviz()
    chains = np.asarray(chains, dtype=float)
    n_c, n_d, d = chains.shape
    names = names or [f"theta{i}" for i in range(d)]
    ds = az.convert_to_dataset({"x": chains})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rhat = np.asarray(az.rhat(ds)["x"].values, dtype=float).reshape(d)
        bulk = np.asarray(az.ess(ds, method="bulk")["x"].values, dtype=float).reshape(d)
        tail = np.asarray(az.ess(ds, method="tail")["x"].values, dtype=float).reshape(d)
    return ChainDiagnostics(list(names), rhat, bulk, tail)


def inference_data(chains: np.ndarray, log_prob: np.ndarray, names: list[str]):
    """An ArviZ InferenceData of the draws (for NetCDF output and ArviZ plots)."""
    az = _arviz()
    posterior = {n: chains[:, :, i] for i, n in enumerate(names)}
    return az.from_dict(posterior=posterior, sample_stats={"lp": log_prob})
