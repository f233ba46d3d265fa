"""Time-domain likelihood under correlated model error: the AR residual model stays calibrated.

A 3-story shear building (one stiffness factor) is driven by a measured base acceleration; the
"measured" floor accelerations are the model's response at the true factor plus a model error that
the analysis model cannot produce: the response of an unmodelled 2.3 Hz resonance (2 % damping,
driven by its own random input), 15 % of the response RMS, plus 1 % white noise. The posterior of
the factor is computed on a fine grid (exact, no sampler), for a record and one 4x longer.

With correlated error the information still grows with the record, so every posterior narrows as
the record grows; what differs is whether the width is honest. The white-noise likelihood treats the
thousands of correlated residual samples as independent: its 95 % intervals miss the truth in most
seeds at either length (its estimate wanders by several of its own standard deviations). The AR(2)
likelihood whitens the residual, and its intervals cover the truth.

Thresholds (``SHM_FULL=1``: 20 seeds, CI: 6). For a calibrated method the number of seeds whose
95 % interval covers the truth is Binomial(n, 0.95). CI requires ``>= n - 3`` of 6: a calibrated
method fails with probability P(X <= 2) < 1e-4, and even at a true coverage of 0.85 it passes with
probability 0.99. The full run requires ``>= 0.8 n`` of 20 (P(X < 16) = 0.016 at 0.95). The
white-noise model must cover in at most half of the seeds at each length (it covers ~0-30 %).
"""

from __future__ import annotations

import numpy as np
from bayes_synth import FULL
from scipy import signal

from shm_ros.core.bayes.timedomain import AccelerationRecord, TimeDomainLikelihood, base_response
from shm_ros.core.models import build_model
from shm_ros.core.structure import structure_from_dict

N_SEEDS = 20 if FULL else 6
FS = 40.0
SECONDS = 60.0
TRUTH = 1.0
CHANNELS = ["f1", "f2", "f3"]
COARSE = np.linspace(0.8, 1.2, 41)


def _model():
    spec = structure_from_dict({
        "name": "three-story", "kind": "shear_building",
        "shear_building": {"floors": [{"mass": 3.0e5, "stiffness": 4.0e8} for _ in range(3)]},
        "damping": {"kind": "rayleigh", "ratios": [0.02, 0.02]},
        "sensors": [{"id": "g0", "at": {"floor": 0}, "direction": "x"}]
        + [{"id": f"f{i}", "at": {"floor": i}, "direction": "x"} for i in (1, 2, 3)],
        "input": {"sensor": "g0"},
        "parameters": [{"name": "k", "applies_to": "shear_building.floors[0,1,2].stiffness",
                        "prior": {"dist": "normal", "mean": 1.0, "std": 0.1}}],
    })
    return build_model(spec)


def _record(model, seed: int, seconds: float) -> AccelerationRecord:
    rng = np.random.default_rng(seed)
    n = int(seconds * FS)
    sos = signal.butter(4, [0.3, 15.0], btype="band", fs=FS, output="sos")
    ag = signal.sosfilt(sos, rng.standard_normal(n))
    y = base_response(model, np.array([TRUTH]), ag, 1.0 / FS, CHANNELS)
    w0, z = 2 * np.pi * 2.6, 0.02  # the unmodelled resonance, exactly discretised
    b, a = signal.cont2discrete(([1.0], [1.0, 2 * z * w0, w0**2]), 1.0 / FS, method="zoh")[:2]
    err = np.column_stack([signal.lfilter(np.ravel(b), a, rng.standard_normal(n)) for _ in CHANNELS])
    rms = np.std(y, axis=0)
    err *= 0.3 * rms / np.std(err, axis=0)
    y = y + err + 0.01 * rms * rng.standard_normal(y.shape)
    return AccelerationRecord(1.0 / FS, ag, y, CHANNELS)


def _grid_posterior(lik) -> tuple[float, float, float, float]:
    """Mean, std and the 95 % interval of the factor (prior N(1, 0.1)): a coarse grid finds the
    peak, a fine grid of +-12 curvature standard deviations around it integrates the posterior."""
    def logpost(g: np.ndarray) -> np.ndarray:
        return lik(g[:, None]) - 0.5 * ((g - 1.0) / 0.1) ** 2

    lp = logpost(COARSE)
    i = int(np.clip(np.argmax(lp), 1, COARSE.size - 2))
    near = np.linspace(COARSE[i - 1], COARSE[i + 1], 81)
    x0 = float(near[np.argmax(logpost(near))])
    h = 1e-4
    c = logpost(x0 + np.array([-h, 0.0, h]))
    curv = -(c[0] - 2 * c[1] + c[2]) / h**2
    sd = 1.0 / np.sqrt(max(curv, 1e-12))
    grid = np.linspace(x0 - 12 * sd, x0 + 12 * sd, 161)
    lp = logpost(grid)
    w = np.exp(lp - lp.max())
    assert w[0] < 1e-6 and w[-1] < 1e-6, "posterior wider than its grid"
    w /= w.sum()
    mean = float(np.dot(w, grid))
    std = float(np.sqrt(np.dot(w, (grid - mean) ** 2)))
    cdf = np.cumsum(w)
    return mean, std, float(np.interp(0.025, cdf, grid)), float(np.interp(0.975, cdf, grid))


def test_ar_residual_model_keeps_intervals_honest():
    model = _model()
    res: dict[tuple[str, float], list] = {}
    for seed in range(N_SEEDS):
        for seconds in (SECONDS, 4 * SECONDS):
            rec = _record(model, 100 + seed, seconds)
            for name, order in (("white", 0), ("ar2", 2)):
                lik = TimeDomainLikelihood(model, rec, ar_order=order)
                if order:  # the AR model is estimated once, at the white-noise estimate (as update does)
                    lik.fix_ar(np.array([_grid_posterior(lik)[0]]))
                res.setdefault((name, seconds), []).append(_grid_posterior(lik))
    cover = {}
    for key, rows in res.items():
        r = np.array(rows)
        cover[key] = int(np.sum((r[:, 2] <= TRUTH) & (TRUTH <= r[:, 3])))
        print(f"{key}: covered {cover[key]}/{N_SEEDS}, median std {np.median(r[:, 1]):.5f}")
    need = N_SEEDS - 3 if not FULL else int(np.ceil(0.8 * N_SEEDS))
    for seconds in (SECONDS, 4 * SECONDS):
        assert cover[("ar2", seconds)] >= need, cover
    # the white-noise model is overconfident at both lengths
    assert all(cover[("white", s)] <= N_SEEDS // 2 for s in (SECONDS, 4 * SECONDS)), cover
    # and the AR model's estimate is the closer one (whitening weights the residual by its spectrum)
    err = {k: np.median(np.abs(np.array(v)[:, 0] - TRUTH)) for k, v in res.items()}
    assert err[("ar2", 4 * SECONDS)] < err[("white", 4 * SECONDS)], err
    # the longer record still informs the AR model: it narrows, about as 1/sqrt(length)
    std = {k: np.median(np.array(v)[:, 1]) for k, v in res.items()}
    ratio = std[("ar2", 4 * SECONDS)] / std[("ar2", SECONDS)]
    assert 0.35 <= ratio <= 0.8, ratio
