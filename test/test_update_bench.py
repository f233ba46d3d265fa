"""Acceptance (CI size) of the updating benchmark: ``python -m bench.bench_update`` has the figures
and checks the speed targets (20,000 likelihood evaluations per second on 2 cores, a converged
emcee posterior in under 60 s); these tests only print the figures and check the results.
"""

from __future__ import annotations

import time

import numpy as np
from threadpoolctl import threadpool_limits

from bayes_synth import building_dict, spec_and_model, synth_modal
from shm_ros.core.bayes.update import UpdateConfig, build_likelihood, update

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


def test_full_emcee_posterior_converges():
    spec, model, obs = _problem()
    c0 = time.process_time()
    post = update(model, obs, UpdateConfig(sampler="emcee", evidence=False, reduction="iirs", seed=0),
                  priors=spec.parameters)
    cpu = time.process_time() - c0
    d = post.diagnostics
    print(f"emcee: {cpu:.1f} CPU-s, R-hat max {d['rhat_max']:.4f}, ESS min {d['ess_min']:.0f}")
    assert d["converged"] and d["rhat_max"] < 1.01 and d["ess_min"] >= 1000
