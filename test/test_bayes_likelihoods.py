"""Modal likelihoods: inverse-gamma marginalisation, fitness J, pairing by MAC, IIRS inside."""

from __future__ import annotations

import numpy as np
import pytest
from bayes_synth import building_dict, girder_dict, spec_and_model, synth_modal
from scipy import integrate

from shm_ros.core.bayes.forward import FullModalPredictor, ReducedModalPredictor, build_predictor
from shm_ros.core.bayes.likelihoods import FitnessLikelihood, GaussianModalLikelihood, InverseGamma, ig_marginal_loglik
from shm_ros.core.bayes.pairing import pair_modes, pair_modes_optimal
from shm_ros.core.modal import mac
from shm_ros.core.observations import ModalObservations

TRUTH = np.array([0.93, 1.06, 0.97])
SENSORS = ["f2", "f4", "f6", "f8"]


@pytest.fixture(scope="module")
def building():
    spec, model = spec_and_model(building_dict())
    obs = synth_modal(model, TRUTH, SENSORS, 30, np.random.default_rng(5))
    return spec, model, obs


def test_inverse_gamma_marginal_matches_quadrature():
    rng = np.random.default_rng(0)
    r = 0.01 * rng.standard_normal(12)
    prior = InverseGamma(2.0, 3e-4)
    ss, n = float(np.sum(r**2)), r.size

    def integrand(log_s2):
        s2 = np.exp(log_s2)
        ll = -0.5 * n * np.log(2 * np.pi * s2) - ss / (2 * s2)
        lp = prior.shape * np.log(prior.scale) - np.log(__import__("math").gamma(prior.shape)) \
            - (prior.shape + 1) * np.log(s2) - prior.scale / s2
        return np.exp(ll + lp + log_s2 - 30.0)

    val, _ = integrate.quad(integrand, -20, 0, limit=400, points=[np.log(ss / n)])
    assert abs(float(ig_marginal_loglik(np.array(ss), n, prior)) - (np.log(val) + 30.0)) < 1e-6


def test_sampled_variance_integrates_to_marginal(building):
    """Integrating the sampled-variance likelihood over the IG prior gives the marginal form."""
    spec, model, obs = building
    one = obs.subset(slice(0, 30))
    one = ModalObservations(one.times, [1], one.frequencies_hz[:, :1], None, [], None)
    pred = FullModalPredictor(model, [], 3)
    prior = InverseGamma(2.0, 1e-4)
    marg = GaussianModalLikelihood(pred, one, use_shapes=False, freq_prior=prior)
    samp = GaussianModalLikelihood(pred, one, use_shapes=False, variance="sampled", freq_prior=prior)
    marg.n_theta = samp.n_theta = 3
    theta = TRUTH * 1.002
    grid = np.linspace(np.log(1e-7), np.log(1e-2), 4001)
    X = np.column_stack([np.repeat(theta[None], grid.size, 0), grid])
    f = samp(X) + samp.extra_logprior(X[:, 3:])
    m = f.max()
    num = m + np.log(np.trapezoid(np.exp(f - m), grid))
    assert abs(num - marg(theta[None])[0]) < 1e-4


def test_likelihood_peaks_near_truth(building):
    spec, model, obs = building
    pred = build_predictor(model, SENSORS, 6, "iirs", n_required=4)
    lik = GaussianModalLikelihood(pred, obs)
    lik.n_theta = 3
    rng = np.random.default_rng(2)
    away = TRUTH[None] * (1 + 0.02 * rng.standard_normal((64, 3)))
    assert lik(TRUTH[None])[0] > np.max(lik(away))


def test_fitness_matches_direct_sum(building):
    spec, model, obs = building
    pred = FullModalPredictor(model, SENSORS, 6)
    lik = FitnessLikelihood(pred, obs, alpha=0.8, beta=0.2, k=0.05)
    theta = np.array([[0.95, 1.0, 1.02]])
    f_model, phi_model = pred(theta)
    idx = pair_modes(obs.mean_frequencies(), obs.reference_shapes(), f_model, phi_model)[0]
    J = 0.0
    for w in range(obs.n_windows):
        for k in range(obs.n_modes):
            J += 0.8 * ((obs.frequencies_hz[w, k] - f_model[0, idx[k]]) / obs.frequencies_hz[w, k]) ** 2
            J += 0.2 * (1 - mac(obs.shapes[w, k], phi_model[0, :, idx[k]]))
    assert abs(lik.fitness(theta)[0] - J) < 1e-9 * J
    assert abs(lik(theta)[0] + J / (2 * 0.05**2)) < 1e-6 * J / 0.005


def test_pairing_uses_shapes_not_order():
    """Two model modes 5 % apart swap order; MAC pairing follows the shapes."""
    rng = np.random.default_rng(0)
    phi = np.linalg.qr(rng.standard_normal((6, 3)))[0]  # three distinct shapes at 6 sensors
    f_obs = np.array([2.0, 3.0, 3.15])
    f_model = np.array([[2.0, 3.12, 3.03]])  # model modes 2 and 3 in swapped frequency order
    phi_model = phi[None].copy()
    idx = pair_modes(f_obs, phi.T, f_model, phi_model)
    assert idx.tolist() == [[0, 1, 2]]
    order = np.argsort(f_model[0])
    assert order.tolist() != [0, 1, 2]  # order alone would pair them wrongly
    assert pair_modes_optimal(f_obs, phi.T, f_model[0], phi_model[0]).tolist() == [0, 1, 2]
    # without shapes the frequency is all there is
    assert pair_modes(f_obs, None, f_model, None).tolist() == [[0, 2, 1]]


def test_iirs_predictor_matches_full_and_expands_shapes(building):
    spec, model, obs = building
    red = ReducedModalPredictor(model, SENSORS, 4)
    full = FullModalPredictor(model, SENSORS, 4)
    thetas = TRUTH[None] * (1 + 0.05 * np.random.default_rng(3).standard_normal((32, 3)))
    fr, pr = red(thetas)
    ff, pf = full(thetas)
    np.testing.assert_allclose(fr, ff, rtol=1e-7)
    assert np.min(mac(np.swapaxes(pr, 1, 2), np.swapaxes(pf, 1, 2))) > 1 - 1e-9
    # expansion with the reduction's own T reproduces the full model's shapes at unmeasured floors
    f1, phi_exp = red.full_shapes(TRUTH)
    sol = model.modes(TRUTH, 4)
    for k in range(4):
        assert mac(phi_exp[:, k], sol.shapes[:, k]) > 1 - 1e-8
    assert red.n_modes == 4 and len(red.masters) == 4


def test_auto_predictor_choice_is_exact():
    spec, model = spec_and_model(girder_dict(5))
    sensors = [s.id for s in spec.sensors]
    pred = build_predictor(model, sensors, 6, "auto", n_required=4)
    ref = FullModalPredictor(model, sensors, 6)
    th = np.array([[1.02, 0.95]])
    np.testing.assert_allclose(pred(th)[0][:, :4], ref(th)[0][:, :4], rtol=1e-6)


def test_unknown_sensor_is_named(building):
    spec, model, obs = building
    with pytest.raises(ValueError, match="'f3'"):
        FullModalPredictor(model, ["f2", "f3"], 4)


def test_posterior_expands_measured_shapes_to_unmeasured_floors(building):
    """The data's shapes at floors 2/4/6/8, expanded with the IIRS transformation of the MAP model,
    match the true shapes at all 8 floors (the building paper's mode-shape expansion)."""
    from shm_ros.core.bayes.update import UpdateConfig, update

    spec, model, obs = building
    post = update(model, obs, UpdateConfig(n_steps=200, rhat_target=1.2, ess_target=100,
                                           evidence=False, reduction="iirs"), priors=spec.parameters)
    mm = post.map_modes
    assert mm["dof_labels"] == model.dof_labels and len(mm["observed_shapes_expanded"]) == 4
    true = model.modes(TRUTH, 4).shapes
    unmeasured = [i for i in range(8) if f"f{i + 1}" not in SENSORS]
    for k in range(4):
        exp_k = np.array(mm["observed_shapes_expanded"][k])
        assert mac(exp_k, true[:, k]) > 0.995
        assert mac(exp_k[unmeasured], true[unmeasured, k]) > 0.99
        assert mac(np.array(mm["model_shapes"][k]), true[:, k]) > 0.9999
