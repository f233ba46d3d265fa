"""Priors of docs/interfaces.md §2: densities, quantiles, parametrisations, bad specifications."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from shm_ros.core.priors import JointPrior, Prior, PriorError, priors_from_specs, weibull_matching

SPECS = [
    ("normal", {"mean": 1.0, "std": 0.1}, stats.norm(1.0, 0.1)),
    ("lognormal", {"mean": 1.2, "std": 0.3},
     stats.lognorm(s=math.sqrt(math.log1p(0.0625)), scale=1.2 / math.sqrt(1.0625))),
    ("weibull", {"scale": 1.1, "shape": 9.0}, stats.weibull_min(9.0, scale=1.1)),
    ("uniform", {"low": 0.5, "high": 1.5}, stats.uniform(0.5, 1.0)),
    ("inverse_gamma", {"shape": 3.0, "scale": 2e-4}, stats.invgamma(3.0, scale=2e-4)),
]


@pytest.mark.parametrize("kind,params,ref", SPECS, ids=[s[0] for s in SPECS])
def test_density_and_quantiles_match_scipy(kind, params, ref):
    p = Prior.make(kind, params, "x")
    u = np.linspace(0.001, 0.999, 41)
    x = ref.ppf(u)
    np.testing.assert_allclose(p.logpdf(x), ref.logpdf(x), rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(p.ppf(u), x, rtol=1e-10)
    outside = {"normal": [], "lognormal": [-1.0, 0.0], "weibull": [-0.5], "uniform": [0.49, 1.51],
               "inverse_gamma": [0.0, -1.0]}[kind]
    assert np.all(np.isneginf(p.logpdf(np.array(outside))))


def test_lognormal_mean_std_are_of_the_factor_itself():
    p = Prior.make("lognormal", {"mean": 1.3, "std": 0.4})
    draws = p.sample(np.random.default_rng(0), 400_000)
    assert abs(draws.mean() - 1.3) < 0.005 and abs(draws.std() - 0.4) < 0.005
    assert abs(p.mean - 1.3) < 1e-12 and abs(p.std - 0.4) < 1e-12


def test_weibull_moment_matching():
    params = weibull_matching(1.0, 0.1)
    p = Prior.make("weibull", params)
    assert abs(p.mean - 1.0) < 1e-9 and abs(p.std - 0.1) < 1e-9


def test_joint_prior_transform_and_batch_logpdf():
    jp = JointPrior([Prior.make(k, v, k) for k, v, _ in SPECS[:4]])
    u = np.random.default_rng(1).random((50, 4))
    x = jp.transform(u)
    expected = sum(ref.logpdf(x[:, i]) for i, (_, _, ref) in enumerate(SPECS[:4]))
    np.testing.assert_allclose(jp.logpdf(x), expected, rtol=1e-10)
    np.testing.assert_allclose(jp.transform(u[0]), x[0])


@pytest.mark.parametrize("spec,msg", [
    ({"name": "E", "prior": {"dist": "gamma", "mean": 1}}, "unknown dist 'gamma'"),
    ({"name": "E", "prior": {"dist": "normal", "mean": 1}}, "needs field 'std'"),
    ({"name": "E", "prior": {"dist": "normal", "mean": 1, "std": -1}}, "'std' must be > 0"),
    ({"name": "E", "prior": {"dist": "uniform", "low": 2, "high": 1}}, "high > low"),
    ({"name": "E", "prior": {"dist": "normal", "mean": "a", "std": 1}}, "must be a number"),
    ({"name": "E"}, "missing 'prior'"),
])
def test_bad_prior_specs_name_parameter_and_field(spec, msg):
    with pytest.raises(PriorError) as exc:
        priors_from_specs([spec])
    assert msg in str(exc.value)
    if "prior" in spec:
        assert "'E'" in str(exc.value)
