"""Adaptive random-walk Metropolis-Hastings, several chains in lock-step."""

from __future__ import annotations

import numpy as np

from shm_ros.core.bayes.samplers import ChainResult, LogProb, SamplerSettings, run_mh

from .base import SAMPLERS, SamplerKind, SamplerName


@SAMPLERS.register(SamplerName.MH)
class MetropolisHastings(SamplerKind):
    def run(self, log_prob: LogProb, center: np.ndarray, cov: np.ndarray, settings: SamplerSettings,
            names: list[str]) -> ChainResult:
        return run_mh(log_prob, center, cov, settings, names)
