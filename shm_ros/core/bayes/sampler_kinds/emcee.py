"""emcee's affine-invariant ensemble sampler with differential-evolution moves, vectorised."""

from __future__ import annotations

import numpy as np

from shm_ros.core.bayes.samplers import ChainResult, LogProb, SamplerSettings, run_emcee

from .base import SAMPLERS, SamplerKind, SamplerName


@SAMPLERS.register(SamplerName.EMCEE)
class Emcee(SamplerKind):
    def run(self, log_prob: LogProb, center: np.ndarray, cov: np.ndarray, settings: SamplerSettings,
            names: list[str]) -> ChainResult:
        return run_emcee(log_prob, center, cov, settings, names)
