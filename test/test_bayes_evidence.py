"""Model evidence by nested sampling against closed forms."""

from __future__ import annotations

import numpy as np
from scipy import stats

from shm_ros.core.bayes.evidence import nested_evidence
from shm_ros.core.priors import JointPrior, Prior


def linear_gaussian(seed: int, design: np.ndarray, mu0, sd0, noise: float, theta_true=None):
    """y = A theta + e with Gaussian prior and noise: closed-form evidence N(y | A mu0, A S0 A' + s2 I)."""
    rng = np.random.default_rng(seed)
    mu0, sd0 = np.asarray(mu0, float), np.asarray(sd0, float)
    theta = mu0 + sd0 * rng.standard_normal(mu0.size) if theta_true is None else theta_true
    y = design @ theta + noise * rng.standard_normal(design.shape[0])
    return y


def log_z_exact(y, A, mu0, sd0, noise):
    cov = A @ np.diag(np.asarray(sd0) ** 2) @ A.T + noise**2 * np.eye(len(y))
    return float(stats.multivariate_normal(A @ np.asarray(mu0), cov).logpdf(y))


def log_lik(y, A, noise):
    def f(X):
        r = y[None] - np.atleast_2d(X) @ A.T
        return -0.5 * np.sum(r**2, axis=1) / noise**2 - 0.5 * len(y) * np.log(2 * np.pi * noise**2)
    return f


def prior_of(mu0, sd0):
    return JointPrior([Prior.make("normal", {"mean": m, "std": s}, f"t{i}") for i, (m, s) in
                       enumerate(zip(mu0, sd0))])


def test_four_parameter_linear_gaussian_ten_seeds():
    mu0, sd0, noise = [1.0, 0.5, -0.3, 2.0], [1.0, 2.0, 0.5, 1.5], 0.5
    hits, errs = 0, []
    for seed in range(10):
        A = np.random.default_rng(100 + seed).standard_normal((20, 4))
        y = linear_gaussian(seed, A, mu0, sd0, noise)
        res = nested_evidence(log_lik(y, A, noise), prior_of(mu0, sd0), n_live=300, seed=seed)
        err = res.log_evidence - log_z_exact(y, A, mu0, sd0, noise)
        errs.append(err)
        hits += abs(err) <= 0.5
    print("log Z errors:", np.round(errs, 3))
    assert hits >= 9, errs


def test_two_model_comparison_picks_the_true_model():
    """Straight line vs quadratic: the generating model has the higher evidence, either way round,
    and the nested-sampling Bayes factor agrees with the closed form."""
    x = np.linspace(-1, 1, 25)
    A_lin = np.column_stack([np.ones_like(x), x])
    A_quad = np.column_stack([np.ones_like(x), x, x**2])
    noise = 0.1
    for seed, truth_is_quad in ((1, True), (2, False)):
        theta = np.array([0.3, 1.0, 0.6]) if truth_is_quad else np.array([0.3, 1.0, 0.0])
        y = A_quad @ theta + noise * np.random.default_rng(seed).standard_normal(x.size)
        lz = {}
        for name, A in (("linear", A_lin), ("quadratic", A_quad)):
            mu0, sd0 = np.zeros(A.shape[1]), np.ones(A.shape[1])
            res = nested_evidence(log_lik(y, A, noise), prior_of(mu0, sd0), n_live=300, seed=seed)
            exact = log_z_exact(y, A, mu0, sd0, noise)
            assert abs(res.log_evidence - exact) < 0.6
            lz[name] = res.log_evidence
        winner = max(lz, key=lz.get)
        assert winner == ("quadratic" if truth_is_quad else "linear"), lz


def test_structural_model_classes_through_update():
    """8-story building, frequencies of 4 modes: one global stiffness factor vs three story groups.

    Data from a building whose lower stories are 12 % softer: the grouped class must win clearly.
    Data from a uniformly stiffer building: both classes fit, and the simpler one must win (the
    Occam factor of the two extra parameters)."""
    from bayes_synth import building_dict, spec_and_model, synth_modal

    from shm_ros.core.bayes.update import UpdateConfig, update
    from shm_ros.core.observations import ModalObservations

    grouped = building_dict()
    single = dict(grouped, parameters=[{"name": "k_all", "applies_to": "shear_building.floors.stiffness",
                                        "prior": {"dist": "normal", "mean": 1.0, "std": 0.15}}])
    spec_g, model_g = spec_and_model(grouped)
    spec_s, model_s = spec_and_model(single)
    cfg = UpdateConfig(reduction="none", use_shapes=False, n_steps=200, rhat_target=1.2,
                       ess_target=100, n_live=150, seed=0)
    for truth, expected in ((np.array([0.88, 1.0, 1.0]), "grouped"), (np.array([1.03] * 3), "single")):
        obs = synth_modal(model_g, truth, ["f2", "f4", "f6", "f8"], 30, np.random.default_rng(7))
        obs = ModalObservations(obs.times, obs.mode_numbers, obs.frequencies_hz)
        lz = {name: update(m, obs, cfg, priors=s.parameters).log_evidence
              for name, (s, m) in (("grouped", (spec_g, model_g)), ("single", (spec_s, model_s)))}
        winner = max(lz, key=lz.get)
        print(f"truth {truth}: log Z {lz}")
        assert winner == expected, (truth, lz)
        assert abs(lz["grouped"] - lz["single"]) > 2.0, lz
