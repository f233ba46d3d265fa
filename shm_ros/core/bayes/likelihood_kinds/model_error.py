"""Modal data with a systematic model error shared by all windows (docs/updating.md)."""

from __future__ import annotations

from shm_ros.core.bayes.likelihoods import weak_error_priors
from shm_ros.core.bayes.model_error import ModelErrorLikelihood

from .base import LIKELIHOODS, Likelihood, LikelihoodInputs, LikelihoodKind, LikelihoodName


@LIKELIHOODS.register(LikelihoodName.MODEL_ERROR)
class ModelError(LikelihoodKind):
    def build(self, inputs: LikelihoodInputs) -> Likelihood:
        c, data = inputs.config, inputs.data
        return ModelErrorLikelihood(
            inputs.predictor, data, use_shapes=bool(inputs.predictor.sensor_ids) and data.has_shapes,
            variance=c.variance, **weak_error_priors(c), pairing=inputs.pairing,
            n_theta=inputs.model.n_parameters)
