"""A likelihood in one file: Gaussian frequency errors, each mode's std its scatter over the windows."""

import numpy as np

from shm_ros.core.bayes.likelihood_kinds.base import LIKELIHOODS, LikelihoodKind, NoNuisance


class _Frequencies(NoNuisance):
    def __init__(self, predictor, frequencies_hz, pairing, n_theta):
        self.predictor, self.f, self.pairing, self.n_theta = predictor, frequencies_hz, pairing, n_theta
        self.std = np.nanstd(frequencies_hz, axis=0, ddof=1)

    def __call__(self, x):
        f_model, _ = self.predictor(np.atleast_2d(x)[:, :self.n_theta])
        r = (self.f[None] - f_model[:, None, self.pairing]) / self.std  # (B, windows, modes)
        return -0.5 * np.nansum(r**2, axis=(1, 2))


@LIKELIHOODS.register("toy-frequencies")
class ToyFrequencies(LikelihoodKind):
    def build(self, inputs):
        return _Frequencies(inputs.predictor, inputs.data.frequencies_hz, inputs.pairing, inputs.model.n_parameters)
