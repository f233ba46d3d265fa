"""Convergence diagnostics of MCMC output (rank-normalised R-hat, bulk/tail ESS) through ArviZ's
array interface (``arviz_stats``: numpy in, numpy out, without ArviZ's plotting stack, so a worker
process starts about 2 s sooner); full ArviZ only for InferenceData (NetCDF output, plots)."""

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
    """Diagnostics of ``chains`` (n_chains, n_draws, d): ArviZ's rank-normalised split R-hat and
    bulk and tail (5 %/95 % quantile) ESS."""
    from arviz_stats.base import array_stats

    chains = np.asarray(chains, dtype=float)
    d = chains.shape[2]
    names = names or [f"theta{i}" for i in range(d)]
    per = np.moveaxis(chains, 2, 0)  # (d, chains, draws): the interface's default axes
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rhat = np.asarray(array_stats.rhat(per), dtype=float).reshape(d)
        bulk = np.asarray(array_stats.ess(per, method="bulk"), dtype=float).reshape(d)
        tail = np.asarray(array_stats.ess(per, method="tail", prob=(0.05, 0.95)), dtype=float).reshape(d)
    return ChainDiagnostics(list(names), rhat, bulk, tail)


def inference_data(chains: np.ndarray, log_prob: np.ndarray, names: list[str]):
    """An ArviZ InferenceData of the draws (for NetCDF output and ArviZ plots)."""
    az = _arviz()
    posterior = {n: chains[:, :, i] for i, n in enumerate(names)}
    return az.from_dict(posterior=posterior, sample_stats={"lp": log_prob})
