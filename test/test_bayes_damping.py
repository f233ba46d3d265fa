"""Damping ratios in the Gaussian modal likelihood (opt-in ``use_damping``).

The model's ratio of every paired mode follows its damping law (Rayleigh: fixed by the two lowest
model modes at each theta); the data are identified ratios scattered by 20 % per window.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from bayes_synth import building_dict, spec_and_model, synth_modal

from shm_ros.core.bayes.forward import FullModalPredictor
from shm_ros.core.bayes.likelihoods import GaussianModalLikelihood
from shm_ros.core.bayes.update import UpdateConfig, update

SENSORS = ["f2", "f4", "f6", "f8"]
TRUTH = np.array([0.93, 1.06, 0.97, 1.4])  # three stiffness groups and a damping factor
DAMPING_SCATTER = 0.2


@pytest.fixture(scope="module")
def damped():
    d = building_dict()
    d["parameters"].append({"name": "zeta", "applies_to": "damping.ratios[*]",
                            "prior": {"dist": "lognormal", "mean": 1.0, "std": 0.5}})
    spec, model = spec_and_model(d)
    rng = np.random.default_rng(8)
    obs = synth_modal(model, TRUTH, SENSORS, 200, rng)
    z = model.modal_damping_ratios(TRUTH, 4)
    obs.damping = z[None] * (1.0 + DAMPING_SCATTER * rng.standard_normal(obs.frequencies_hz.shape))
    return spec, model, obs


def test_damping_residuals_match_a_direct_sum(damped):
    spec, model, obs = damped
    lik = GaussianModalLikelihood(FullModalPredictor(model, SENSORS, 6), obs, use_damping=True)
    lik.n_theta = 4
    theta = np.array([[0.95, 1.0, 1.0, 1.2]])
    _, _, ss_d = lik._residuals(theta)
    assert ss_d is not None and obs.damping is not None
    z_model = model.modal_damping_ratios(theta[0], 4)
    z_bar = obs.damping.mean(axis=0)
    direct = (((obs.damping - z_model[None]) / z_bar[None]) ** 2).sum(axis=0)
    np.testing.assert_allclose(ss_d[0], direct, rtol=1e-10)
    assert "sigma2_damping_mode1" in lik.variance_names


def test_damping_informs_a_damping_parameter_only_when_enabled(damped):
    """With damping in the likelihood the damping factor is found (200 windows of 20 % scatter
    over 4 modes: std of the factor ~1 %, so 5 % is 5 sigma); without it the posterior of that
    factor is its prior (lognormal, std 0.5)."""
    spec, model, obs = damped
    short = UpdateConfig(likelihood="gaussian", sampler="mh", n_steps=600, rhat_target=1.05, ess_target=300.0, evidence=False)
    with_d = update(model, obs, replace(short, use_damping=True), priors=spec.parameters)
    z = with_d.parameters["zeta"]
    assert abs(z.mean / TRUTH[3] - 1) < 0.05 and z.std < 0.05, z
    assert "sigma2_damping_mode1" in with_d.noise
    for name, t in zip(("k_low", "k_mid", "k_top"), TRUTH[:3], strict=True):
        assert abs(with_d.parameters[name].mean - t) < 0.03
    without = update(model, obs, short, priors=spec.parameters)
    assert without.parameters["zeta"].std > 0.3
