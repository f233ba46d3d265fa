"""The model error of a prediction, learnt out of sample over the calibration events.

A calibration's own residual (its in-sample NRMS) understates the error of a prediction: the
parameters were fitted to those very records. Here every calibration event is left out in turn
(leave-one-event-out cross-validation): the model's parameters are fitted by least squares to the
other events (log factors from the posterior's MAP, :func:`fit_theta`), and the left-out event is
predicted. Its residual ``r(t)``, the pre-event noise variance ``s0`` and the local mean square of
the prediction ``m(t)`` give, per strong-motion sample, the relative error variance that would just
put the sample inside the band ``+- z sqrt(s0 + r^2 m(t))``:

    q(t) = max(0, (r(t)^2 / z^2 - s0) / m(t)).

Per fold, the ``level`` quantile of ``q`` is the ``r^2`` whose band would have held ``level`` of that
left-out event's strong-motion samples; the channel's model-error term is their geometric mean over
the folds (a typical event's band holds ``level``; the events' scatter about it is their own). Where the
folds show it (three or more events, slope beyond two standard errors), ``r^2`` follows the input's
PGA as a power law (``amplitude_slope``; an event far stronger than the calibration's is more
nonlinear), else it is constant. Unmeasured floors and drift ratios take the mean over the channels
(the same term, through the model, see :mod:`.predict`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.special import ndtri  # the normal quantile

from shm_ros.core.models.base import AffineModel
from shm_ros.core.response import sensor_outputs
from shm_ros.core.response.batch import batch_responses, single_blas_thread

from .config import PredictConfig
from .record import EventRecord
from .signals import local_mean_square, prepare, strong_motion

_MIN_FOLDS_FOR_SLOPE = 3


@dataclass
class ModelError:
    """Per channel the relative error variance ``rel2`` at the reference PGA ``pga_ref``; ``rel2``
    of another event is ``rel2 (pga / pga_ref) ** amplitude_slope``."""

    rel2: dict[str, float]
    pga_ref: float
    amplitude_slope: float = 0.0
    pga_max: float = 0.0  # the strongest calibration event's input PGA
    folds: list[dict[str, Any]] = field(default_factory=list)
    method: str = "leave-one-event-out"

    def rel2_at(self, channel: str | None, pga: float) -> float:
        base = self.rel2.get(channel, float(np.mean(list(self.rel2.values())))) if channel else \
            float(np.mean(list(self.rel2.values())))
        if self.amplitude_slope and pga > 0 and self.pga_ref > 0:
            base *= (pga / self.pga_ref) ** self.amplitude_slope
        return float(base)

    def to_json(self) -> dict[str, Any]:
        return {"method": self.method, "relative_error": {k: float(np.sqrt(v)) for k, v in self.rel2.items()},
                "pga_ref_m_s2": self.pga_ref, "amplitude_slope": self.amplitude_slope,
                "calibration_pga_max_m_s2": self.pga_max, "folds": self.folds}


def input_pga(record: EventRecord, cfg: PredictConfig) -> float:
    """Peak of the (baseline-corrected) first input record."""
    u, _, _ = prepare(record, cfg)
    return float(np.max(np.abs(u[0]))) if u.size else 0.0


def responses(model: AffineModel, theta: np.ndarray, record: EventRecord, cfg: PredictConfig) -> np.ndarray:
    """(channels, N) model accelerations of the record's channels at ``theta``."""
    u, _, _ = prepare(record, cfg)
    outs = sensor_outputs(model, record.channel_ids)
    return next(batch_responses(model, theta[None, :], u, 1.0 / record.fs, outs, chunk=1))[1][0]


def fit_theta(model: AffineModel, events: list[EventRecord], theta0: np.ndarray, cfg: PredictConfig,
              max_nfev: int = 60) -> np.ndarray:
    """The parameters (log factors from ``theta0``) minimising the records' summed squared
    residuals, each channel weighted by its records' RMS (the least-squares fit of the model
    class); ``theta0`` when there is nothing to fit."""
    if not events:
        return np.asarray(theta0, float)
    data = []
    for ev in events:
        _, y, _ = prepare(ev, cfg)
        w = 1.0 / np.maximum(np.sqrt(np.nanmean(y ** 2, axis=0)), 1e-12)
        data.append((ev, np.nan_to_num(y.T), w, np.isfinite(y.T)))

    def resid(x: np.ndarray) -> np.ndarray:
        th = np.asarray(theta0, float) * np.exp(x)
        parts = []
        for ev, y, w, ok in data:
            r = (y - responses(model, th, ev, cfg)) * w[:, None]
            parts.append(np.where(ok, r, 0.0).ravel() / np.sqrt(y.size))
        return np.concatenate(parts)

    with single_blas_thread():
        sol = least_squares(resid, np.zeros(len(theta0)), bounds=(-1.5, 1.5), x_scale=0.1, max_nfev=max_nfev)
    return np.asarray(theta0, float) * np.exp(sol.x)


def cross_validated_error(model: AffineModel, events: list[EventRecord], theta0: np.ndarray,
                          config: PredictConfig | None = None) -> ModelError:
    """The model error of :mod:`this module <.model_error>` from ``events`` (at least two, sharing
    their channels), starting every fit from ``theta0`` (the posterior's MAP)."""
    cfg = (config or PredictConfig()).validate()
    if len(events) < 2:
        raise ValueError("a cross-validated model error needs at least two calibration events")
    ids = events[0].channel_ids
    z = float(ndtri(0.5 + cfg.level / 2))
    q: dict[str, list[np.ndarray]] = {c: [] for c in ids}
    folds: list[dict[str, Any]] = []
    pgas = [input_pga(ev, cfg) for ev in events]
    for i, ev in enumerate(events):
        if ev.channel_ids != ids:
            raise ValueError(f"window {ev.window_id}: channels {ev.channel_ids} differ from {ids}")
        theta = fit_theta(model, events[:i] + events[i + 1:], theta0, cfg)
        u, y, n_pre = prepare(ev, cfg)
        yh = responses(model, theta, ev, cfg)
        lms = local_mean_square(yh, ev.fs, cfg.envelope_s)
        strong = strong_motion(u[0])
        fold: dict[str, Any] = {"window_id": ev.window_id, "pga_m_s2": pgas[i], "relative_error": {}}
        for c, cid in enumerate(ids):
            r = y[:, c] - yh[c]
            s0 = float(np.nanvar(r[:n_pre])) if np.isfinite(r[:n_pre]).sum() > 1 else 0.0
            rs, ms = r[strong], lms[c, strong]
            ok = np.isfinite(rs) & (ms > 0)
            qc = np.maximum(0.0, (rs[ok] ** 2 / z ** 2 - s0) / ms[ok])
            q[cid].append(qc)
            fold["relative_error"][cid] = float(np.sqrt(np.quantile(qc, cfg.level))) if qc.size else None
        folds.append(fold)
    rel2 = {c: _typical([float(np.quantile(x, cfg.level)) for x in v if x.size]) for c, v in q.items()}
    slope = _amplitude_slope(folds, pgas)
    pga_ref = float(np.exp(np.mean(np.log(np.maximum(pgas, 1e-12)))))
    return ModelError(rel2, pga_ref, slope, float(max(pgas)), folds)


def _typical(values: list[float]) -> float:
    """The geometric mean of the folds' ``r^2`` (the band holds ``level`` of a typical event's
    samples; the folds' scatter is the events' own)."""
    v = np.asarray([x for x in values if x > 0], float)
    return float(np.exp(np.mean(np.log(v)))) if v.size else 0.0


def _amplitude_slope(folds: list[dict[str, Any]], pgas: list[float]) -> float:
    """Slope of log r^2 over log PGA across the folds, where it differs from 0 by two standard
    errors (three folds at least); else 0."""
    if len(folds) < _MIN_FOLDS_FOR_SLOPE or min(pgas) <= 0:
        return 0.0
    r = [np.mean([v for v in f["relative_error"].values() if v]) for f in folds]
    if min(r) <= 0:
        return 0.0
    x, yv = np.log(pgas), 2 * np.log(r)
    if np.ptp(x) < 1e-6:
        return 0.0
    A = np.column_stack([np.ones_like(x), x])
    coef, res, *_ = np.linalg.lstsq(A, yv, rcond=None)
    dof = len(x) - 2
    if dof < 1:
        return 0.0
    s2 = float(np.sum((yv - A @ coef) ** 2)) / dof
    se = float(np.sqrt(s2 / np.sum((x - x.mean()) ** 2)))
    return float(coef[1]) if abs(coef[1]) > 2 * se else 0.0
