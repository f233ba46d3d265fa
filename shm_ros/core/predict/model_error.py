"""The model error of a prediction, learnt out of sample over the calibration events, and the
equivalent-linear parameters of an event of a given amplitude.

A structure that yields or whose damping grows with the shaking is, for a linear model, a different
linear structure in every event: the best fit of each calibration event alone (its *equivalent-linear
parameters*, :func:`fit_theta` from the posterior's MAP) moves with the event's input PGA (more
damping and softer springs in the strong events, the elastic structure in the weak ones). A
prediction therefore centres the posterior's draws on the parameters of its own amplitude: the
calibration events' fits interpolated in log parameter over log PGA, held at the nearest calibration
event's outside their range (no extrapolation of a trend the events did not show; see ``theta_at``).

A calibration's own residual understates the error of a prediction. Every calibration event is
left out in turn (leave-one-event-out cross-validation): it is predicted at the parameters the
*other* events give for its PGA, and its residual ``r(t)``, the pre-event noise variance ``s0`` and
the local mean square of the prediction ``m(t)`` give, per strong-motion sample, the relative error
variance that would just put the sample inside the band ``+- z sqrt(s0 + r^2 m(t))``:

    q(t) = max(0, (r(t)^2 / z^2 - s0) / m(t)).

The ``level`` quantile of ``q`` is the ``r^2`` whose band would have held ``level`` of that event's
strong-motion samples. The same quantile of each event at its own fit is the model class's floor
``a`` (what no choice of parameters removes: torsion read by sensors off the centre of mass,
unmodelled coupling); the left-out events' excess over it grows with how far their PGA lies from the
other events' (the equivalent-linear parameters of one amplitude describe another the worse the
further apart they are). Per channel

    r^2(pga) = a + b D(pga)^2,   D = |ln(pga / nearest calibration PGA)|,

``a`` the geometric mean of the events' own floors, ``b`` the least-squares slope of the folds'
excess ``r_i^2 - a`` over ``D_i^2`` (through the origin, not below zero). An event between or at the
calibration events' PGAs gets the floor plus the interpolation's share; one further out the wider
band its distance calls for, up to the largest distance a fold was held out at (``D`` is taken at
most that far, ``distance_max``). Beyond it the folds say nothing about how the error grows: the
equivalent-linear parameters are held at the nearest event's there rather than extrapolated, and
the error is not extrapolated either (the out-of-calibration warning says the event lies there,
:mod:`.risk`). Without that ceiling two calibration events of close PGAs (both folds at one small
distance ``D_f``) would widen a later event's band by ``(D / D_f)^2`` - a factor 6 for an event 30 %
stronger than two events 12 % apart - from a slope the folds never measured. Unmeasured floors and
drift ratios take the mean over the channels (the same term, through the model, see
:mod:`.predict`).
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


@dataclass
class ModelError:
    """Per channel the relative error variance: ``rel2`` (the floor ``a``) plus ``distance_rel2``
    (``b``) times the squared log-PGA distance to the nearest calibration event; the calibration
    events' input PGAs ``pgas`` and equivalent-linear parameters ``thetas`` (one row per event)."""

    rel2: dict[str, float]
    pgas: list[float]
    thetas: list[list[float]]
    distance_rel2: dict[str, float] = field(default_factory=dict)
    unmeasured_rel2: float = 0.0  # at least this for outputs no channel reads (the folds' typical error)
    # per parameter the spread of ln(equivalent-linear parameter) about the interpolation (held-out events)
    log_spread: list[float] = field(default_factory=list)
    folds: list[dict[str, Any]] = field(default_factory=list)
    method: str = "leave-one-event-out"
    distance_max: float = float("inf")  # the largest distance a fold was held out at (``D`` goes no further)

    @property
    def pga_max(self) -> float:
        """The strongest calibration event's input PGA."""
        return float(max(self.pgas)) if self.pgas else 0.0

    def distance(self, pga: float) -> float:
        """``|ln(pga / nearest calibration PGA)|`` (0 without a PGA)."""
        p = np.asarray([x for x in self.pgas if x > 0], float)
        return float(np.min(np.abs(np.log(pga / p)))) if pga > 0 and p.size else 0.0

    def rel2_at(self, channel: str | None, pga: float) -> float:
        """``a + b D^2`` of ``channel``, ``D`` at most ``distance_max``; an output no channel reads
        (None) the channels' mean, at least ``unmeasured_rel2``."""
        d2 = min(self.distance(pga), self.distance_max) ** 2
        if channel is None:
            return max(self.unmeasured_rel2, _mean(self.rel2) + _mean(self.distance_rel2) * d2)
        a = self.rel2.get(channel, _mean(self.rel2))
        return float(a + self.distance_rel2.get(channel, _mean(self.distance_rel2)) * d2)

    def theta_at(self, pga: float) -> np.ndarray | None:
        """The equivalent-linear parameters of an event of input PGA ``pga``: the calibration
        events' interpolated in log over log PGA, held at the nearest event's outside their range
        (None without them)."""
        return _interpolate(self.pgas, self.thetas, pga)

    def to_json(self) -> dict[str, Any]:
        return {"method": self.method, "relative_error": {k: float(np.sqrt(v)) for k, v in self.rel2.items()},
                "distance_relative_error": {k: float(np.sqrt(v)) for k, v in self.distance_rel2.items()},
                "calibration_pgas_m_s2": list(self.pgas), "equivalent_linear_parameters": self.thetas,
                "calibration_pga_max_m_s2": self.pga_max, "distance_max": _finite(self.distance_max),
                "unmeasured_relative_error": float(np.sqrt(self.unmeasured_rel2)),
                "log_parameter_spread": list(self.log_spread), "folds": self.folds}


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def _mean(d: dict[str, float]) -> float:
    return float(np.mean(list(d.values()))) if d else 0.0


def _interpolate(pgas: list[float], thetas: list[list[float]], pga: float) -> np.ndarray | None:
    if not thetas:
        return None
    th = np.log(np.asarray(thetas, float))
    if len(pgas) == 1 or pga <= 0:
        return np.exp(th.mean(axis=0))
    order = np.argsort(pgas)
    x = np.log(np.maximum(np.asarray(pgas, float)[order], 1e-12))
    return np.exp(np.array([np.interp(np.log(pga), x, th[order, k]) for k in range(th.shape[1])]))


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


def _relative_errors(model: AffineModel, ev: EventRecord, theta: np.ndarray, cfg: PredictConfig, z: float
                     ) -> dict[str, float]:
    """Per channel the ``level`` quantile of ``q(t)`` (module doc) of ``ev`` predicted at ``theta``."""
    u, y, n_pre = prepare(ev, cfg)
    yh = responses(model, theta, ev, cfg)
    lms = local_mean_square(yh, ev.fs, cfg.envelope_s)
    strong = strong_motion(u[0])
    out = {}
    for c, cid in enumerate(ev.channel_ids):
        r = y[:, c] - yh[c]
        s0 = float(np.nanvar(r[:n_pre])) if np.isfinite(r[:n_pre]).sum() > 1 else 0.0
        rs, ms = r[strong], lms[c, strong]
        ok = np.isfinite(rs) & (ms > 0)
        qc = np.maximum(0.0, (rs[ok] ** 2 / z ** 2 - s0) / ms[ok])
        if qc.size:
            out[cid] = float(np.quantile(qc, cfg.level))
    return out


def cross_validated_error(model: AffineModel, events: list[EventRecord], theta0: np.ndarray,
                          config: PredictConfig | None = None) -> ModelError:
    """The model error and equivalent-linear parameters of :mod:`this module <.model_error>` from
    ``events`` (at least two, sharing their channels), every fit started from ``theta0`` (the
    posterior's MAP)."""
    cfg = (config or PredictConfig()).validate()
    if len(events) < 2:
        raise ValueError("a cross-validated model error needs at least two calibration events")
    ids = events[0].channel_ids
    for ev in events:
        if ev.channel_ids != ids:
            raise ValueError(f"window {ev.window_id}: channels {ev.channel_ids} differ from {ids}")
    z = float(ndtri(0.5 + cfg.level / 2))
    pgas = [input_pga(ev, cfg) for ev in events]
    thetas = [fit_theta(model, [ev], theta0, cfg) for ev in events]
    own = [_relative_errors(model, ev, th, cfg, z) for ev, th in zip(events, thetas, strict=True)]
    floor = {c: _geometric_mean([o[c] for o in own if c in o]) for c in ids}
    folds: list[dict[str, Any]] = []
    excess: dict[str, list[tuple[float, float]]] = {c: [] for c in ids}
    held_out: dict[str, list[float]] = {c: [] for c in ids}
    others = [[k for k in range(len(events)) if k != i] for i in range(len(events))]
    centre = [_interpolate([pgas[k] for k in o], [list(thetas[k]) for k in o], pgas[i]) for i, o in enumerate(others)]
    dev = np.array([np.log(thetas[i] / c) for i, c in enumerate(centre)])
    spread = [float(x) for x in np.sqrt(np.mean(np.square(dev), axis=0))]
    for i, ev in enumerate(events):
        th = np.asarray(centre[i])
        r2 = _relative_errors(model, ev, th, cfg, z)
        d = ModelError({}, [pgas[k] for k in others[i]], []).distance(pgas[i])
        for c, v in r2.items():
            excess[c].append((d, v - floor[c]))
            held_out[c].append(v)
        folds.append({"window_id": ev.window_id, "pga_m_s2": pgas[i], "distance": d,
                      "relative_error": {c: float(np.sqrt(v)) for c, v in r2.items()},
                      "own_fit_relative_error": {c: float(np.sqrt(v)) for c, v in own[i].items()},
                      "equivalent_linear_parameters": [float(x) for x in thetas[i]]})
    slope = {c: _slope(v) for c, v in excess.items()}
    unmeasured = _mean({c: _geometric_mean(v) for c, v in held_out.items()})
    return ModelError(floor, [float(p) for p in pgas], [[float(x) for x in th] for th in thetas], slope,
                      unmeasured, spread, folds, distance_max=max(f["distance"] for f in folds))


def _geometric_mean(values: list[float]) -> float:
    """The geometric mean of the positive ``r^2`` (a typical event's; the scatter is the events' own)."""
    v = np.asarray([x for x in values if x > 0], float)
    return float(np.exp(np.mean(np.log(v)))) if v.size else 0.0


def _slope(points: list[tuple[float, float]]) -> float:
    """Least-squares slope through the origin of the excess ``r^2 - a`` over ``D^2``, not below 0."""
    d2 = np.asarray([p[0] ** 2 for p in points], float)
    e = np.asarray([p[1] for p in points], float)
    den = float(np.sum(d2 ** 2))
    return max(0.0, float(np.sum(d2 * e)) / den) if den > 0 else 0.0
