"""The bridge paper's fitness likelihood exp(-J / 2k^2)."""

from __future__ import annotations

from shm_ros.core.bayes.likelihoods import FitnessLikelihood

from .base import LIKELIHOODS, Likelihood, LikelihoodInputs, LikelihoodKind, LikelihoodName


@LIKELIHOODS.register(LikelihoodName.FITNESS)
class Fitness(LikelihoodKind):
    def build(self, inputs: LikelihoodInputs) -> Likelihood:
        c = inputs.config
        return FitnessLikelihood(inputs.predictor, inputs.data, alpha=c.alpha, beta=c.beta, k=c.k, j=c.fitness_j,
                                 pairing=inputs.pairing, n_theta=inputs.model.n_parameters)
