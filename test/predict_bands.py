"""Calibrate on some events, predict the others, score the bands against a truth campaign
(test/predict_truth.py): the measured channels' strong-motion coverage, peaks, sharpness and NRMS
against the oracle (the model class fitted to the predicted events themselves), and the truth's
peaks at unmeasured floors and drift ratios inside their intervals."""

from __future__ import annotations

from typing import Any

import numpy as np
from predict_truth import PredictCampaign

from shm_ros.core.bayes.records import RecordSet
from shm_ros.core.bayes.timedomain import AccelerationRecord
from shm_ros.core.bayes.update import UpdateConfig, update
from shm_ros.core.models import build_model
from shm_ros.core.models.base import AffineModel
from shm_ros.core.predict import (
    EventPrediction,
    PosteriorDraws,
    PredictConfig,
    draws_from_posterior,
    event_from_window,
    predict_event,
)
from shm_ros.core.predict.model_error import cross_validated_error, fit_theta
from shm_ros.core.predict.signals import prepare
from shm_ros.core.structure import structure_from_dict


def calibrate(model: AffineModel, spec: Any, windows: list, cfg: PredictConfig, steps: int = 150, ar_order: int = 0):
    """The joint time-domain posterior of ``windows`` (emcee, 8 walkers), each event its own error
    variance per channel (a relative model error weighs the events alike)."""
    recs = []
    for w in windows:
        u, y, _ = prepare(event_from_window(w, model), cfg)
        recs.append(AccelerationRecord(1 / w.sample_rate_hz, u, y, event_from_window(w, model).channel_ids))
    uc = UpdateConfig(likelihood="time", n_chains=8, n_steps=steps, max_steps=steps, evidence=False,
                      ess_target=50, rhat_target=1.2, residual_ar_order=ar_order, variance_per_event=True)
    return update(model, RecordSet(recs), uc, spec.parameters)


def predict_campaign(pc: PredictCampaign, seed: int, n_draws: int = 100, steps: int = 150
                     ) -> tuple[AffineModel, list[EventPrediction], PosteriorDraws]:
    spec = structure_from_dict(pc.structure)
    model = build_model(spec)
    cfg = PredictConfig(n_draws=n_draws, seed=seed)
    post = calibrate(model, spec, pc.calibration, cfg, steps)
    draws = draws_from_posterior(post, model, n_draws, np.random.default_rng(seed), cfg.relative_error)
    cal = [event_from_window(w, model) for w in pc.calibration]
    draws = draws.with_model_error(cross_validated_error(model, cal, draws.theta_map, cfg))
    return model, [predict_event(model, event_from_window(w, model), draws, cfg) for w in pc.predicted], draws


def _oracle(model: AffineModel, events: list, theta_map: np.ndarray, cfg: PredictConfig) -> PosteriorDraws:
    """The model class's least-squares fit to the predicted events themselves: the better (lower
    median NRMS) of the fits started from the posterior's MAP and from the nominal parameters (a
    local optimiser; one start can stop in a poorer minimum)."""
    best, score = None, np.inf
    for start in (theta_map, model.nominal_theta()):
        th = fit_theta(model, events, start, cfg)
        d = PosteriorDraws(th[None, :], th)
        s = float(np.median([c.scores["nrms_pct"] for ev in events for c in predict_event(model, ev, d, cfg).channels
                             if c.measured]))
        if s < score:
            best, score = d, s
    assert best is not None
    return best


def score_campaign(pc: PredictCampaign, seed: int, n_draws: int = 100, steps: int = 150) -> dict[str, Any]:
    """Per event and measured channel: NRMS (updated, nominal, oracle), strong-motion coverage, peak
    inside, mean half-width and RMS error; per truth series: peak inside."""
    model, preds, draws = predict_campaign(pc, seed, n_draws, steps)
    cfg = PredictConfig(n_draws=0, seed=seed)
    events = [event_from_window(w, model) for w in pc.predicted]
    od = _oracle(model, events, draws.theta_map, cfg)
    out: dict[str, Any] = {"nrms": [], "oracle": [], "coverage": [], "peaks": [], "half": [], "rmse": [],
                           "better": [], "hidden": [], "hidden_names": []}
    for ev, p in zip(events, preds, strict=True):
        po = predict_event(model, ev, od, cfg)
        cov, better = [], []
        for c in p.channels:
            if not c.measured:
                continue
            s = c.scores
            out["nrms"].append(s["nrms_pct"])
            out["oracle"].append(po.channel(c.name).scores["nrms_pct"])
            cov.append(s["coverage_95_strong"])
            out["peaks"].append(bool(s["peak_inside"]))
            assert c.values is not None
            st = p.strong
            out["half"].append(float(np.mean((c.upper - c.lower)[st] / 2)))
            out["rmse"].append(float(np.sqrt(np.nanmean((c.values - c.mean)[st] ** 2))))
            better.append((s["nrms_pct"], s["nrms_pct_nominal"]))
        out["coverage"].append(float(np.median(cov)))
        out["better"].append(bool(np.median([b[0] for b in better]) < np.median([b[1] for b in better])))
        for name, v in pc.truth[p.window_id].items():
            c = p.channel(name)
            peak = float(np.max(np.abs(v)))
            out["hidden"].append(c.peak_ci[0] <= peak <= c.peak_ci[1])
            out["hidden_names"].append(name)
    return out
