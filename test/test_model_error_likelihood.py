"""Model-error likelihood: honest uncertainty when the truth lies outside the model's class.

Data (``model_form_synth``): the simulator's girder truth with rotationally restrained bearings,
finer mesh, scattered properties and misplaced sensors, analysed with the nominal girder (pinned
bearings; E_scale and bearing_scale); per-window frequencies follow the air temperature (daily
cycle and slow drift of the campaign), with 0.2-0.5 % identification scatter.

* Prediction: updated on the first 75 % of 1,152 ten-minute windows (8 days), the 95 %
  posterior-predictive intervals of the frequencies must cover 90-98 % of the last 25 % of windows,
  pooled over seeds and modes.
* Width: the 95 % interval of E_scale from 1,152 windows is at least half that from the first 144
  (a likelihood with independent windows gives about 1/sqrt(8) = 0.35; checked on one seed).

Seeds: ``SHM_FULL=1`` runs 20, CI 3. Coverage indicators within a seed are strongly correlated
(the temperature of the held-out days moves all of a mode's windows together), so the binomial over
windows does not apply; the spread is that of the per-seed pooled coverage, measured on seeds 0-19
with short chains: mean 0.949, standard deviation 0.036 over seeds (range 0.86-0.996). The full run
asserts the stated 90-98 % band on the mean of 20 seeds (standard error 0.008: the band's ends are
6 and 4 standard errors away). The mean of 3 seeds has a standard deviation of 0.021; CI requires
>= 0.89 (2.8 standard deviations below the mean: a correct method passes with probability > 99.5 %
in the normal approximation) and leaves the upper end to the full run (3 seeds cannot resolve it at
99 %). The width ratio of a correct method is 0.89-1.42 over those seeds, far above 0.5.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from bayes_synth import FULL
from model_form_synth import analysis_model, model_form_table

from shm_ros.core.bayes.update import UpdateConfig, build_likelihood, update

N_SEEDS = 20 if FULL else 3
N_WINDOWS = 1152
CONFIG: dict[str, Any] = dict(sampler="emcee", evidence=False, n_chains=24, n_steps=1500 if FULL else 300,
              rhat_target=1.01 if FULL else 1.05, ess_target=1000 if FULL else 300)
BAND = (0.90, 0.98) if FULL else (0.89, 1.0)
_cache: dict = {}


def _posterior(seed: int, n: int, likelihood: str = "model-error"):
    key = (seed, n, likelihood)
    if key not in _cache:
        spec, model = analysis_model()
        obs = model_form_table(seed, N_WINDOWS).subset(slice(0, n))
        cfg = UpdateConfig(**CONFIG, seed=seed, likelihood=likelihood)
        _cache[key] = (update(model, obs, cfg, priors=spec.parameters), obs, cfg)
    return _cache[key]


def _width(post) -> float:
    lo, hi = post.parameters["E_scale"].ci95
    return hi - lo


def test_predictive_intervals_cover_later_windows():
    spec, model = analysis_model()
    n_cal = 3 * N_WINDOWS // 4
    hits, total = 0, 0
    for seed in range(N_SEEDS):
        post, cal, cfg = _posterior(seed, n_cal)
        assert post.diagnostics["likelihood"] == "model-error"
        later = model_form_table(seed, N_WINDOWS).subset(slice(n_cal, N_WINDOWS)).frequencies_hz
        lik, _ = build_likelihood(model, cal, cfg)
        lik.n_theta = model.n_parameters
        rng = np.random.default_rng(seed)
        draws = lik.predictive_frequencies(post.samples[rng.choice(len(post.samples), 2000)], rng)
        lo, hi = np.quantile(draws, [0.025, 0.975], axis=0)
        inside = (later >= lo) & (later <= hi)
        hits += int(inside.sum())
        total += inside.size
        print(f"seed {seed}: coverage per mode {inside.mean(axis=0).round(3)}; model-error scale "
              f"{post.noise['model_error_scale']['mean']:.4f}")
        # the model cannot fit the truth: the inferred model error is far above the scatter's share
        assert post.noise["model_error_scale"]["mean"] > 0.003
    coverage = hits / total
    print(f"pooled coverage {coverage:.3f} over {N_SEEDS} seeds")
    assert BAND[0] <= coverage <= BAND[1], coverage


def test_width_does_not_shrink_with_windows_beyond_model_error():
    ratios = [_width(_posterior(s, N_WINDOWS)[0]) / _width(_posterior(s, 144)[0]) for s in range(N_SEEDS)]
    print(f"E_scale 95 % width ratio (1152 vs 144 windows): {np.round(ratios, 3)}")
    assert np.mean(ratios) >= 0.5 and min(ratios) >= 0.4, ratios
    # the independent-window likelihood narrows as 1/sqrt(windows): the criterion tells them apart
    g = _width(_posterior(0, N_WINDOWS, "gaussian")[0]) / _width(_posterior(0, 144, "gaussian")[0])
    print(f"gaussian likelihood: width ratio {g:.3f}")
    assert g < 0.5, g


class _FixedPredictor:
    """A predictor whose model frequency of the single mode is theta[0] Hz (no shapes)."""

    sensor_ids: list[str] = []
    n_modes = 1

    def __call__(self, theta):
        theta = np.atleast_2d(theta)
        return theta[:, :1].copy(), np.zeros((theta.shape[0], 0, 1))


def _one_mode(n: int, seed: int = 0):
    from shm_ros.core.observations import ModalObservations

    rng = np.random.default_rng(seed)
    f = 2.0 * (1.0 + 0.01 + 0.004 * rng.standard_normal(n))
    return ModalObservations(times=np.arange(n) * 600.0, mode_numbers=[1], frequencies_hz=f[:, None])


def test_marginal_equals_joint_gaussian_integrated_numerically():
    """The closed form (W and mean split, sigma^2 by quadrature, s on its grid) against the joint
    density N(x | r, sigma^2 I + s^2 11^T) integrated over the IG prior of sigma^2 and the
    log-uniform prior of s by brute-force quadrature; and the sampled-variance form integrated over
    log sigma^2 against the marginal."""
    from scipy.stats import multivariate_normal

    from shm_ros.core.bayes.likelihoods import InverseGamma, set_pairing
    from shm_ros.core.bayes.model_error import FREQ_SCALE_RANGE, ModelErrorLikelihood

    obs = _one_mode(5)
    prior = InverseGamma.weak(0.01)
    kw = dict(use_shapes=False, freq_prior=prior, time_correlation=False, n_grid=200, n_quad=40)
    lik = ModelErrorLikelihood(_FixedPredictor(), obs, **kw)
    set_pairing(lik, np.array([0]))  # one data mode, one model mode
    theta = np.array([[2.01]])
    x = obs.frequencies_hz[:, 0] / lik.stats.f_ref[0]
    r = theta[0, 0] / lik.stats.f_ref[0]
    n = x.size
    ls = np.linspace(np.log(FREQ_SCALE_RANGE[0]), np.log(FREQ_SCALE_RANGE[1]), 300)
    lv = np.linspace(np.log(1e-7), np.log(1.0), 600)
    a, b = prior.shape, prior.scale
    S, V = np.meshgrid(np.exp(ls), np.exp(lv), indexing="ij")
    d = x - r
    # N(d | 0, v I + s^2 11^T) in closed form (Sherman-Morrison), checked against scipy at 3 points
    logn = (-0.5 * n * np.log(2 * np.pi) - 0.5 * (n - 1) * np.log(V) - 0.5 * np.log(V + n * S * S)
            - 0.5 * (np.sum(d * d) - n * d.mean() ** 2) / V - 0.5 * n * d.mean() ** 2 / (V + n * S * S))
    for i, j in ((10, 100), (150, 300), (299, 599)):
        cov = V[i, j] * np.eye(n) + S[i, j] ** 2 * np.ones((n, n))
        assert abs(multivariate_normal.logpdf(d, np.zeros(n), cov) - logn[i, j]) < 1e-8
    ig = a * np.log(b) - math.lgamma(a) - (a + 1) * np.log(V) - b / V
    dens = logn + ig + np.log(V)
    m = dens.max()
    brute = m + np.log(np.trapezoid(np.trapezoid(np.exp(dens - m), lv, axis=1), ls) / np.ptp(ls))
    brute -= n * np.log(lik.stats.f_ref[0])  # density of Hz, as the likelihood reports
    assert abs(lik(theta)[0] - brute) < 2e-2, (lik(theta)[0], brute)

    samp = ModelErrorLikelihood(_FixedPredictor(), obs, variance="sampled", **kw)
    set_pairing(samp, np.array([0]))
    samp.n_theta = lik.n_theta = 1
    X = np.column_stack([np.full(lv.size, theta[0, 0]), lv])
    f = samp(X) + samp.extra_logprior(X[:, 1:])
    num = f.max() + np.log(np.trapezoid(np.exp(f - f.max()), lv))
    assert abs(num - lik(theta)[0]) < 2e-2, (num, lik(theta)[0])
