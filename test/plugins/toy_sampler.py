"""A sampler in one file: plain random-walk Metropolis, four chains, fixed length, Laplace proposal."""

import numpy as np

from shm_ros.core.bayes.diagnostics import chain_diagnostics
from shm_ros.core.bayes.sampler_kinds.base import SAMPLERS, SamplerKind
from shm_ros.core.bayes.samplers import ChainResult


@SAMPLERS.register("toy-random-walk")
class ToyRandomWalk(SamplerKind):
    def run(self, log_prob, center, cov, settings, names):
        rng = np.random.default_rng(settings.seed)
        n_c, n, d = 4, 2 * settings.n_steps, center.size
        chol = np.linalg.cholesky(2.38**2 / d * cov)
        x = center + rng.standard_normal((n_c, d)) @ chol.T
        lp = log_prob(x)
        xs, lps, acc = [], [], 0
        for _ in range(n):
            prop = x + rng.standard_normal((n_c, d)) @ chol.T
            lp_new = log_prob(prop)
            ok = np.log(rng.random(n_c)) < lp_new - lp
            x, lp, acc = np.where(ok[:, None], prop, x), np.where(ok, lp_new, lp), acc + ok.sum()
            xs.append(x)
            lps.append(lp)
        burn = n // 4
        chains, lps_kept = np.stack(xs[burn:], axis=1), np.stack(lps[burn:], axis=1)
        diag = chain_diagnostics(chains, names)
        converged = diag.meets(settings.rhat_target, settings.ess_target)
        return ChainResult(self.name, chains, lps_kept, acc / (n * n_c), burn, n, n * n_c, diag, converged)
