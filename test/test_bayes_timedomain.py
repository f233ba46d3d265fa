"""Time-domain likelihood (building paper eq. 27) on a short earthquake-like record.

The record is simulated by a different route from the likelihood's modal filters: the full
first-order state space of the building is integrated by ``scipy.signal.lsim`` at four times the
sample rate and decimated, and 3 % noise is added per channel.
"""

from __future__ import annotations

import numpy as np
from bayes_synth import building_dict, spec_and_model
from scipy import signal

from shm_ros.core.bayes.timedomain import AccelerationRecord, TimeDomainLikelihood, base_response
from shm_ros.core.bayes.update import UpdateConfig, update

TRUTH = np.array([0.93, 1.06, 0.97])
CHANNELS = ["f2", "f4", "f6", "f8"]


def _record(model, seed: int, fs: float = 50.0, seconds: float = 12.0, noise: float = 0.03,
            fine: int = 4):
    rng = np.random.default_rng(seed)
    n = int(seconds * fs * fine)
    t = np.arange(n) / (fs * fine)
    sos = signal.butter(4, [0.3, 12.0], btype="band", fs=fs * fine, output="sos")
    ag = signal.sosfilt(sos, rng.standard_normal(n)) * np.exp(-((t - 4.0) / 2.5) ** 2)
    ag *= 1.0 / np.max(np.abs(ag))
    K, M, C = model.stiffness(TRUTH), model.mass(TRUTH), model.damping(TRUTH)
    nd = model.n_dof
    Mi = np.linalg.inv(M)
    A = np.block([[np.zeros((nd, nd)), np.eye(nd)], [-Mi @ K, -Mi @ C]])
    B = np.concatenate([np.zeros(nd), -np.ones(nd)])[:, None]
    S = model.sensor_matrix(CHANNELS)
    Cout = S @ np.hstack([-Mi @ K, -Mi @ C])  # absolute acceleration
    _, y, _ = signal.lsim((A, B, Cout, np.zeros((len(CHANNELS), 1))), ag, t)
    y, ag = y[::fine], ag[::fine]
    y = y + noise * np.std(y, axis=0) * rng.standard_normal(y.shape)
    return AccelerationRecord(1.0 / fs, ag, y, CHANNELS)


def test_modal_filter_response_matches_state_space():
    spec, model = spec_and_model(building_dict())
    # same sampling: lsim (input linear between samples) and the exact modal filters agree
    rec = _record(model, 0, noise=0.0, fine=1)
    y = base_response(model, TRUTH, rec.input_accel, rec.dt, CHANNELS)
    nrms = np.linalg.norm(y - rec.outputs, axis=0) / np.linalg.norm(rec.outputs, axis=0)
    assert np.all(nrms < 1e-3), nrms
    # the test data (integrated at 4x the rate, then decimated) differ by a few percent only
    rec = _record(model, 0, noise=0.0)
    y = base_response(model, TRUTH, rec.input_accel, rec.dt, CHANNELS)
    nrms = np.linalg.norm(y - rec.outputs, axis=0) / np.linalg.norm(rec.outputs, axis=0)
    assert np.all(nrms < 0.05), nrms


def test_time_likelihood_recovers_story_stiffness():
    spec, model = spec_and_model(building_dict())
    rec = _record(model, 1)
    lik = TimeDomainLikelihood(model, rec)
    assert lik(TRUTH[None])[0] > lik((TRUTH * 1.01)[None])[0]
    cfg = UpdateConfig(likelihood="time", sampler="emcee", evidence=False, n_chains=16, n_steps=250,
                       rhat_target=1.1, ess_target=200, seed=1)
    post = update(model, rec, cfg, priors=spec.parameters)
    for i, n in enumerate(post.parameter_names):
        s = post.parameters[n]
        assert abs(s.mean - TRUTH[i]) <= max(3 * s.std, 0.002), (n, s)
        assert abs(s.mean - TRUTH[i]) <= 0.02 * TRUTH[i]
    assert post.fit["nrms_mean"] < 0.06
    assert set(post.noise) == {f"sigma2_accel_{c}" for c in CHANNELS}


def test_sampled_channel_variance_integrates_to_marginal():
    """One channel: integrating the sampled-variance likelihood over its IG prior gives the
    marginal likelihood used by default."""
    spec, model = spec_and_model(building_dict())
    rec = _record(model, 3, seconds=6.0)
    one = AccelerationRecord(rec.dt, rec.input_accel, rec.outputs[:, -1:], ["f8"])
    marg = TimeDomainLikelihood(model, one)
    samp = TimeDomainLikelihood(model, one, variance="sampled")
    theta = TRUTH * 1.003
    grid = np.linspace(np.log(1e-8), np.log(1e1), 6001)
    X = np.column_stack([np.repeat(theta[None], grid.size, 0), grid])
    ss = samp.residual_ss(theta)[0]  # one simulation; the grid only varies the variance
    N = samp.n_innovations  # residual samples after the AR model's conditioning samples
    f = -0.5 * N * np.log(2 * np.pi * np.exp(grid)) - 0.5 * ss / np.exp(grid) + samp.extra_logprior(X[:, 3:])
    m = f.max()
    num = m + np.log(np.trapezoid(np.exp(f - m), grid))
    assert abs(num - marg(theta[None])[0]) < 1e-3
    # the sampled form itself evaluates to the same expression
    assert abs(samp(X[:1])[0] - (f[0] - samp.extra_logprior(X[:1, 3:])[0])) < 1e-6 * abs(f[0])


def test_variance_per_event_weighs_each_record_by_its_own_error():
    """A joint likelihood with a variance per record (``variance_per_event``) is the sum of the
    records' own likelihoods; pooled, a record ten times stronger decides the sum of squares."""
    from shm_ros.core.bayes.records import JointTimeDomainLikelihood, RecordSet

    _, model = spec_and_model(building_dict())
    weak, strong = _record(model, 1), _record(model, 2)
    strong = AccelerationRecord(strong.dt, 10 * strong.input_accel, 10 * strong.outputs, strong.channel_ids)
    data = RecordSet([weak, strong])
    x = np.vstack([TRUTH, 1.05 * TRUTH, [1.1, 0.9, 1.0]])
    own = JointTimeDomainLikelihood(model, data, ar_order=0, per_record=True)(x)
    parts = [TimeDomainLikelihood(model, r, ar_order=0)(x) for r in data.records]
    np.testing.assert_allclose(own, parts[0] + parts[1], rtol=1e-10)
    pooled = JointTimeDomainLikelihood(model, data, ar_order=0)
    ss = pooled.record_ss(x)
    assert np.all(ss[1] > 50 * ss[0])  # pooled, the weak record hardly counts
    assert not np.allclose(pooled(x), own)
