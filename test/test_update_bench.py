"""Acceptance (CI size) of the updating benchmark: ``python -m bench.bench_update`` has the figures
and checks the speed targets (20,000 likelihood evaluations per second on 2 cores, a converged
emcee posterior in under 60 s); these tests print the figures and check the results against the
truth the data were simulated from: the likelihood peaks at the truth, the posterior holds it and is
far narrower than the prior. A likelihood that returns zeros fails both (shown below by a planted one).
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from bayes_synth import building_dict, spec_and_model, synth_modal
from threadpoolctl import threadpool_limits

from shm_ros.core.bayes.likelihood_kinds.base import LIKELIHOODS, LikelihoodKind, NoNuisance
from shm_ros.core.bayes.update import Posterior, UpdateConfig, build_likelihood, update

TRUTH = np.array([0.93, 1.06, 0.97])


def _problem():
    spec, model = spec_and_model(building_dict())
    obs = synth_modal(model, TRUTH, ["f2", "f4", "f6", "f8"], 50, np.random.default_rng(0))
    return spec, model, obs


def test_modal_likelihood_with_iirs_throughput():
    spec, model, obs = _problem()
    lik, pred = build_likelihood(model, obs, UpdateConfig(reduction="iirs"))
    assert type(pred).__name__ == "ReducedModalPredictor"
    X = TRUTH[None] * (1 + 0.01 * np.random.default_rng(1).standard_normal((256, 3)))
    with threadpool_limits(1, "blas"):
        lik(X)
        n, c0 = 0, time.process_time()
        while time.process_time() - c0 < 1.5:
            lik(X)
            n += X.shape[0]
        rate = n / (time.process_time() - c0)
    print(f"modal likelihood with IIRS: {rate:,.0f} evaluations per CPU-second")
    values = lik(X)
    assert values.shape == (X.shape[0],) and np.all(np.isfinite(values))
    assert np.allclose(lik(X[:3]), values[:3])  # a batch is evaluated row by row
    assert not _misplaced_peak(lik)


def _misplaced_peak(lik) -> list[str]:
    """The likelihood at the truth must beat every point 3 % away along each parameter (50 windows
    of 0.3-1 % frequency noise pin each factor to about 1 %)."""
    away = np.vstack([TRUTH * (1 + s * 0.03 * np.eye(3)[i]) for i in range(3) for s in (-1, 1)])
    at, off = lik(TRUTH[None])[0], lik(away)
    return [f"likelihood at {a} ({v:.2f}) is not below the truth's ({at:.2f})" for a, v in zip(away, off, strict=True)
            if not v < at]


def _far_from_truth(post: Posterior) -> list[str]:
    """Each parameter's posterior holds the truth (4 posterior std: a correct posterior fails with
    probability < 1e-4 per parameter) and is much narrower than its prior (std 0.15)."""
    bad = []
    for name, t in zip(post.parameter_names, TRUTH, strict=True):
        p = post.parameters[name]
        if not abs(p.mean - t) < 4 * p.std:
            bad.append(f"{name}: mean {p.mean:.4f} +- {p.std:.4f} is more than 4 std from the truth {t}")
        if not p.std < 0.03:
            bad.append(f"{name}: posterior std {p.std:.4f} is not far below the prior's 0.15")
    return bad


def test_full_emcee_posterior_converges():
    spec, model, obs = _problem()
    c0 = time.process_time()
    post = update(model, obs, UpdateConfig(sampler="emcee", evidence=False, reduction="iirs", seed=0),
                  priors=spec.parameters)
    cpu = time.process_time() - c0
    d = post.diagnostics
    print(f"emcee: {cpu:.1f} CPU-s, R-hat max {d['rhat_max']:.4f}, ESS min {d['ess_min']:.0f}")
    assert d["converged"] and d["rhat_max"] < 1.01 and d["ess_min"] >= 1000
    assert not _far_from_truth(post), _far_from_truth(post)


class _Zeros(NoNuisance):
    """A planted fault: a likelihood that ignores the data."""

    def __call__(self, x):
        return np.zeros(np.atleast_2d(x).shape[0])


@pytest.fixture
def zeros_likelihood():
    @LIKELIHOODS.register("zeros")
    class Zeros(LikelihoodKind):
        def build(self, inputs):
            return _Zeros()

    yield "zeros"
    LIKELIHOODS.unregister("zeros")


def test_a_likelihood_returning_zeros_fails_the_checks(zeros_likelihood):
    spec, model, obs = _problem()
    assert _misplaced_peak(_Zeros())
    post = update(model, obs, UpdateConfig(likelihood=zeros_likelihood, n_steps=300, rhat_target=1.1, ess_target=100,
                                           evidence=False, seed=0), priors=spec.parameters)
    assert _far_from_truth(post)
