"""Gaussian prediction error on frequencies, shapes and optionally damping ratios, windows independent."""

from __future__ import annotations

from shm_ros.core.bayes.likelihoods import GaussianModalLikelihood, InverseGamma, weak_error_priors

from .base import LIKELIHOODS, Likelihood, LikelihoodInputs, LikelihoodKind, LikelihoodName


@LIKELIHOODS.register(LikelihoodName.GAUSSIAN)
class Gaussian(LikelihoodKind):
    uses_damping = True

    def build(self, inputs: LikelihoodInputs) -> Likelihood:
        c, data = inputs.config, inputs.data
        return GaussianModalLikelihood(
            inputs.predictor, data, use_shapes=bool(inputs.predictor.sensor_ids) and data.has_shapes,
            variance=c.variance, **weak_error_priors(c), use_damping=c.use_damping,
            damping_prior=InverseGamma.weak(c.damping_error_guess, c.ig_shape), pairing=inputs.pairing,
            n_theta=inputs.model.n_parameters)
