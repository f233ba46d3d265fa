"""``update()`` as one call: samplers agree, variance treatments agree, bad data do not crash it."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from bayes_synth import building_dict, spec_and_model, synth_modal

from shm_ros.core.bayes.update import UpdateConfig, build_likelihood, joint_prior_for, update

TRUTH = np.array([0.93, 1.06, 0.97])
SENSORS = ["f2", "f4", "f6", "f8"]
FAST: dict[str, Any] = dict(n_steps=400, rhat_target=1.03, ess_target=400, evidence=False)


@pytest.fixture(scope="module")
def problem():
    spec, model = spec_and_model(building_dict())
    obs = synth_modal(model, TRUTH, SENSORS, 50, np.random.default_rng(21))
    return spec, model, obs


@pytest.fixture(scope="module")
def reference(problem):
    spec, model, obs = problem
    return update(model, obs, UpdateConfig(sampler="emcee", seed=1, **FAST), priors=spec.parameters)


def _agree(a, b, rel_std=0.25):
    for n in a.parameter_names:
        pa, pb = a.parameters[n], b.parameters[n]
        assert abs(pa.mean - pb.mean) < 0.5 * pa.std, (n, pa, pb)
        assert abs(pb.std / pa.std - 1) < rel_std, (n, pa, pb)


def test_mh_agrees_with_emcee(problem, reference):
    spec, model, obs = problem
    mh = update(model, obs, UpdateConfig(sampler="mh", seed=2, **FAST), priors=spec.parameters)
    assert 0.15 <= mh.diagnostics["acceptance"] <= 0.4
    _agree(reference, mh)


def test_sampled_variances_agree_with_marginalised(problem):
    """Frequencies only: theta plus 4 sampled log-variances vs the variances integrated out."""
    spec, model, obs = problem
    quick = {**FAST, "rhat_target": 1.05, "ess_target": 300}
    marg = update(model, obs, UpdateConfig(likelihood="gaussian", use_shapes=False, seed=3, **quick),
                  priors=spec.parameters)
    sv = update(model, obs, UpdateConfig(likelihood="gaussian", use_shapes=False, variance="sampled", seed=3, **quick),
                priors=spec.parameters)
    assert len(sv.chain_names) == 3 + 4
    _agree(marg, sv)
    # the sampled frequency-error std of mode 1 is near the 0.3 % the data were made with
    s2 = sv.noise["sigma2_f_mode1"]["mean"]
    assert 0.002 < np.sqrt(s2) < 0.0045


def test_map_is_the_densest_point(problem, reference):
    """The log posterior recomputed from the prior and the likelihood directly: ``log_prob`` holds
    it at every kept draw, and no draw is denser than the reported MAP."""
    spec, model, obs = problem
    config = UpdateConfig(sampler="emcee", seed=1, **FAST)
    prior = joint_prior_for(model, config, spec.parameters)
    likelihood, _ = build_likelihood(model, obs, config)
    assert likelihood.n_extra == 0 and reference.samples.shape[1] == 3  # theta only (marginal)

    def log_post(theta: np.ndarray) -> np.ndarray:
        theta = np.atleast_2d(theta)
        return prior.logpdf(theta) + likelihood(theta)

    rng = np.random.default_rng(0)
    best = int(np.argmax(reference.log_prob))
    some = np.concatenate([[best], rng.choice(len(reference.log_prob), 20, replace=False)])
    assert np.allclose(log_post(reference.samples[some]), reference.log_prob[some], rtol=0, atol=1e-6)
    theta_map = reference.theta("map")
    assert log_post(theta_map)[0] >= reference.log_prob[best] - 1e-9
    theta_mean = reference.theta("mean")
    std = np.array([reference.parameters[n].std for n in reference.parameter_names])
    assert np.all(np.abs(theta_map - theta_mean) < 0.5 * std)


def test_bad_data_and_wide_priors_do_not_crash(problem):
    spec, model, obs = problem
    obs = obs.subset(slice(0, 20))
    obs.frequencies_hz[:, 2] = np.nan  # a mode never found
    obs.frequencies_hz[3, :] = np.nan  # a window without modes
    obs.shapes[5, 1, 2] = np.nan  # one shape component missing
    wide = [{"name": n, "prior": {"dist": "normal", "mean": 1.0, "std": 0.8}} for n in model.parameter_names]
    post = update(model, obs, UpdateConfig(n_steps=200, rhat_target=1.1, ess_target=100, n_live=50),
                  priors=wide)
    assert any("mode(s) [3]" in w for w in post.warnings)
    assert post.log_evidence is not None and np.isfinite(post.log_evidence)
    for i, n in enumerate(post.parameter_names):
        assert abs(post.parameters[n].mean - TRUTH[i]) < 0.03


def test_errors_name_the_problem(problem):
    spec, model, obs = problem
    with pytest.raises(ValueError, match="likelihood"):
        update(model, obs, UpdateConfig(likelihood="nope"), priors=spec.parameters)
    with pytest.raises(ValueError, match="k_low"):
        update(model, obs, UpdateConfig(), priors=spec.parameters[1:])
    with pytest.raises(TypeError, match="AccelerationRecord"):
        update(model, obs, UpdateConfig(likelihood="time"), priors=spec.parameters)


def test_summary_record_matches_the_message_definition(reference):
    """Every field of PosteriorSummary.msg / ParameterEstimate.msg (except the header) is filled."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "msg_defs" / "msg"

    def fields(name):
        out = []
        for line in (root / name).read_text().splitlines():
            line = line.split("#")[0].strip()
            if line:
                out.append(line.split()[1])
        return out

    rec = reference.summary_record("eight-story")
    assert set(fields("PosteriorSummary.msg")) - {"header"} == set(rec)
    assert set(fields("ParameterEstimate.msg")) == set(rec["parameters"][0])
    assert rec["n_windows"] == 50 and rec["sampler"] == "emcee" and np.isnan(rec["log_evidence"])
    p = rec["parameters"][0]
    assert p["ci95_low"] < p["mean"] < p["ci95_high"] and p["rhat"] < 1.1 and p["ess"] > 100
