"""MH (adaptive, lock-step chains) and emcee on targets with known moments."""

from __future__ import annotations

import numpy as np
import pytest

from shm_ros.core.bayes.samplers import (SamplerSettings, find_map, laplace_covariance, run_emcee,
                                         run_mh)

MEAN = np.array([1.0, -2.0, 0.5])
COV = np.array([[0.04, 0.018, 0.0], [0.018, 0.09, -0.02], [0.0, -0.02, 0.01]])
PREC = np.linalg.inv(COV)


def log_gauss(x: np.ndarray) -> np.ndarray:
    r = np.atleast_2d(x) - MEAN
    return -0.5 * np.einsum("bi,ij,bj->b", r, PREC, r)


def log_banana(x: np.ndarray) -> np.ndarray:
    """Skewed (non-Gaussian) 2-D target with a hard bound at x0 > 0 (like a stiffness factor)."""
    x = np.atleast_2d(x)
    lx = np.log(np.clip(x[:, 0], 1e-300, None))
    out = -0.5 * (lx / 0.3) ** 2 - lx - 0.5 * ((x[:, 1] - x[:, 0]) / 0.1) ** 2
    return np.where(x[:, 0] > 0, out, -np.inf)


def test_map_and_laplace_recover_gaussian():
    starts = np.random.default_rng(0).normal(0, 3, (200, 3))
    x, lp = find_map(log_gauss, starts, np.ones(3))
    np.testing.assert_allclose(x, MEAN, atol=1e-5)
    np.testing.assert_allclose(laplace_covariance(log_gauss, x, np.ones(3)), COV, rtol=1e-3, atol=1e-6)


@pytest.mark.parametrize("sampler", ["mh", "emcee"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_gaussian_moments_and_diagnostics(sampler, seed):
    settings = SamplerSettings(sampler=sampler, n_steps=2000, seed=seed, max_steps=30000)
    run = run_mh if sampler == "mh" else run_emcee
    res = run(log_gauss, MEAN + 0.3, COV, settings, ["a", "b", "c"])
    flat = res.flat
    assert res.converged and res.diagnostics.rhat_max < 1.01 and res.diagnostics.ess_min >= 1000
    # Monte Carlo error of the mean is std / sqrt(ESS): allow 5 of those
    tol = 5 * np.sqrt(np.diag(COV) / res.diagnostics.ess_min)
    assert np.all(np.abs(flat.mean(axis=0) - MEAN) < tol)
    np.testing.assert_allclose(np.cov(flat.T), COV, rtol=0.15, atol=0.003)
    if sampler == "mh":
        assert 0.15 <= res.acceptance <= 0.40
        assert res.burn_in > 0 and res.chains.shape[0] == 8


def test_mh_on_skewed_bounded_target():
    x0 = np.array([1.0, 1.0])
    res = run_mh(log_banana, x0, np.diag([0.09, 0.1]), SamplerSettings("mh", n_steps=4000, seed=3),
                 ["k", "y"])
    k = res.flat[:, 0]
    # x0 is lognormal(0, 0.3): mean exp(0.045), median 1
    assert abs(k.mean() - np.exp(0.045)) < 0.03
    assert abs(np.median(k) - 1.0) < 0.03
    assert np.all(k > 0)


def test_not_converged_is_reported():
    res = run_mh(log_gauss, MEAN, COV, SamplerSettings("mh", n_steps=60, burn_in=50, max_steps=110,
                                                       ess_target=5000), ["a", "b", "c"])
    assert not res.converged
    assert any("without meeting" in w for w in res.warnings)
