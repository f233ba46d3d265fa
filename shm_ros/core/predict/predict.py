"""Predict one event: the model driven by the measured input, compared with the measured outputs.

For the nominal model, the MAP and every posterior draw the response comes from the exact
time-domain solver (:mod:`shm_ros.core.response`, batched by :mod:`.batch`), from rest at the
window's start after the baseline correction of every record (:mod:`.signals`). The
posterior-predictive distribution of a channel at a sample is the mixture over draws of
``N(y_draw(t), sigma_draw^2(t))`` (error model: :mod:`.draws`); the band is its centre +- z times
its exact second moment about the centre. The centre is the draws' mean, or, with a model error
learnt over calibration events (:mod:`.model_error`), the response at the event's own
equivalent-linear parameters (the MAP moved to the event's input PGA; the draws are moved with
it): the mean of draws with different frequencies is a smeared response no draw resembles. The
measured channels' error term was learnt out of sample on those very channels (it holds the
parameters' event-to-event scatter); the outputs no channel reads (unmeasured floors, drift
ratios) have no record to learn it from, so their draws also carry the calibration events'
spread of equivalent-linear parameters through the model. Peak intervals are quantiles of each draw's peak of
``y_draw + e_draw`` plus one error draw at its time (see ``_peaks``). Unmeasured floors and
interstory drifts are outputs of the same model (every floor is a DOF of the full model); with
``unmeasured: expanded`` (default) the unmeasured floors' accelerations also get the measured
floors' residual expanded on the model's mode shapes (:mod:`.expansion`), the same for every draw.
Drifts are model displacements consistent with the measured input, never integrated records.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.special import ndtri  # the normal quantile

from shm_ros.core.models.base import AffineModel
from shm_ros.core.response import Output, Quantity, drift_outputs, node_row, sensor_outputs
from shm_ros.core.response.batch import batch_responses, single_blas_thread

from .config import PredictConfig, Unmeasured
from .draws import PosteriorDraws, nominal_draws
from .expansion import expansion_matrix
from .record import EventRecord
from .signals import local_mean_square, nrms_pct, prepare, strong_motion


@dataclass
class ChannelPrediction:
    """One predicted location: a sensor (``measured``), an unmeasured floor or a story drift."""

    name: str
    quantity: str  # "acceleration" (m/s^2) | "drift" (m) | "drift_ratio" (-)
    measured: bool
    mean: np.ndarray
    std: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    map: np.ndarray
    nominal: np.ndarray
    values: np.ndarray | None = None  # measured, baseline-corrected
    peak_mean: float = float("nan")
    peak_ci: tuple[float, float] = (float("nan"), float("nan"))
    scores: dict[str, float | bool | None] = field(default_factory=dict)
    # an unmeasured floor that also gets the measured floors' residual of this event (:mod:`.expansion`)
    expanded: bool = False
    # per draw: its peak |y| and the error standard deviation at the peak's time (the peak's
    # predictive distribution is the mixture of |N(top, sigma^2)|; :mod:`.risk`)
    peak_top: np.ndarray = field(default_factory=lambda: np.zeros(0))
    peak_sigma: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass
class EventPrediction:
    window_id: str
    start_ns: int
    fs: float
    pga_m_s2: float
    is_event: bool
    channels: list[ChannelPrediction]
    strong: slice  # the strong-motion part of the input (5-95 % of its Arias intensity)
    n_pre: int  # pre-event samples (baseline and noise floor)
    n_draws: int
    source: str
    notes: list[str] = field(default_factory=list)
    input_pga_m_s2: float = 0.0  # peak of the baseline-corrected input record
    model_error: dict[str, Any] | None = None  # the cross-validated model error used (JSON), if any
    risk: dict[str, Any] | None = None  # drift exceedance and warnings (:func:`.risk.event_risk`)

    def channel(self, name: str) -> ChannelPrediction:
        for c in self.channels:
            if c.name == name:
                return c
        raise KeyError(name)


def prediction_outputs(model: AffineModel, channel_ids: list[str]) -> list[tuple[Output, str]]:
    """Measured sensors' accelerations, then (shear buildings) every floor no sensor sits on and
    every story's drift ratio (drift in m when the story heights are not given)."""
    outs = [(o, "acceleration") for o in sensor_outputs(model, channel_ids)]
    if model.kind != "shear_building":
        return outs
    seen = {int(np.flatnonzero(o.row[:-1])[0]) for o, _ in outs
            if np.count_nonzero(o.row[:-1]) == 1 and o.row[-1] == 0}
    for k in range(model.n_dof):
        if k not in seen:
            e = np.zeros(model.n_dof)
            e[k] = 1.0
            outs.append((Output(f"floor{k + 1}", Quantity.ACCELERATION, node_row(model, e)), "acceleration"))
    ratio = model.story_heights is not None
    outs += [(o, "drift_ratio" if ratio else "drift") for o in drift_outputs(model, ratio=ratio)]
    return outs


def event_rng(seed: int, window_id: str) -> np.random.Generator:
    """The error draws of one window: the same whoever predicts it and in whatever order."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), zlib.crc32(window_id.encode())]))


def predict_event(model: AffineModel, record: EventRecord, draws: PosteriorDraws | None,
                  config: PredictConfig | None = None) -> EventPrediction:
    """The prediction of ``record`` by ``model`` under ``draws`` (None: the nominal model only)."""
    with single_blas_thread():  # small matrices: a BLAS thread pool only waits (see .batch)
        return _predict_event(model, record, draws, config)


def _predict_event(model: AffineModel, record: EventRecord, draws: PosteriorDraws | None,
                   config: PredictConfig | None) -> EventPrediction:
    cfg = (config or PredictConfig()).validate()
    fs, dt = record.fs, 1.0 / record.fs
    draws = draws if draws is not None else nominal_draws(model, cfg.relative_error)
    u, y, n_pre = prepare(record, cfg)
    pga = float(np.max(np.abs(u[0]))) if u.shape[1] else 0.0
    # the equivalent-linear parameters of this event's amplitude (the measured channels' draws) and,
    # for the outputs no channel reads, their spread over events as well (see the module doc)
    spread = draws.at_amplitude(pga, np.random.default_rng(
        np.random.SeedSequence([int(cfg.seed), zlib.crc32(record.window_id.encode()), 1])))
    draws = draws.at_amplitude(pga)
    spec = prediction_outputs(model, record.channel_ids)
    outs = [o for o, _ in spec]
    nm = len(record.channel_ids)
    N = u.shape[1]

    def one(theta: np.ndarray) -> np.ndarray:
        return np.concatenate([Y for _, Y in batch_responses(model, theta[None, :], u, dt, outs, chunk=1)])[0]

    y_nom = one(model.nominal_theta())
    y_map = one(draws.theta_map)
    hidden, corr = _expanded_residual(model, draws.theta_map, spec, nm, y, y_map, cfg)
    y_map[hidden] += corr
    # error model (see .draws): floor from the pre-event residual, relative part in time
    s0 = np.zeros(len(outs))
    for c in range(nm):
        r = y[:n_pre, c] - y_map[c, :n_pre]
        s0[c] = float(np.nanvar(r)) if np.isfinite(r).sum() > 1 else 0.0
    accel = np.array([q == "acceleration" for _, q in spec])
    s0[nm:] = np.where(accel[nm:], np.mean(s0[:nm]) if nm else 0.0, 0.0)
    lms = local_mean_square(y_map, fs, cfg.envelope_s)
    rel2 = draws.rel2_event([*record.channel_ids, *[None] * (len(outs) - nm)], pga)  # (n_draws, o)

    rng = event_rng(cfg.seed, record.window_id)
    S1 = np.zeros((len(outs), N))
    S2 = np.zeros((len(outs), N))
    peaks = np.empty((draws.n, len(outs)))
    tops = np.empty((draws.n, len(outs)))
    sigs = np.empty((draws.n, len(outs)))
    everything = np.arange(len(outs))
    parts = [(draws.theta, everything)] if np.array_equal(spread.theta, draws.theta) else \
        [(draws.theta, everything[:nm]), (spread.theta, everything[nm:])]  # one pass when no spread
    for theta, idx in parts:
        if not idx.size:
            continue
        h = np.isin(hidden, idx)
        for a, Y in batch_responses(model, theta, u, dt, [outs[i] for i in idx], chunk=cfg.chunk,
                                    threads=cfg.threads):
            Y[:, hidden[h] - idx[0]] += corr[h][None]
            S1[idx] += Y.sum(axis=0)
            S2[idx] += np.einsum("bon,bon->on", Y, Y)
            b = a + Y.shape[0]
            tops[a:b, idx], sigs[a:b, idx] = _peaks(Y, s0[idx], rel2[a:b][:, idx], lms[idx])
            peaks[a:b, idx] = np.abs(tops[a:b, idx] + sigs[a:b, idx] * rng.standard_normal((b - a, idx.size)))
    # the centre: with a learnt model error the response at the event's equivalent-linear
    # parameters, else the draws' mean; the band's variance is the draws' second moment about it
    mean = y_map if draws.model_error is not None else S1 / draws.n
    second = S2 / draws.n - 2 * mean * S1 / draws.n + mean ** 2
    var = np.maximum(second, 0.0) + s0[:, None] + np.mean(rel2, axis=0)[:, None] * lms
    std = np.sqrt(var)
    z = float(ndtri(0.5 + cfg.level / 2))
    q = (50 * (1 - cfg.level), 50 * (1 + cfg.level))
    strong = strong_motion(u[0])

    channels = []
    for c, (o, kind) in enumerate(spec):
        lo, hi = mean[c] - z * std[c], mean[c] + z * std[c]
        pk = np.percentile(peaks[:, c], q)
        ch = ChannelPrediction(o.name, kind, c < nm, mean[c], std[c], lo, hi, y_map[c], y_nom[c],
                               peak_mean=float(np.max(np.abs(mean[c]))), peak_ci=(float(pk[0]), float(pk[1])),
                               peak_top=tops[:, c], peak_sigma=sigs[:, c])
        ch.expanded = bool(c in set(hidden.tolist()))
        if c < nm:
            ch.values = y[:, c]
            ch.scores = channel_scores(y[:, c], mean[c], y_map[c], y_nom[c], lo, hi, pk, strong)
        channels.append(ch)
    me = draws.model_error
    return EventPrediction(record.window_id, record.start_ns, fs, record.pga_m_s2, record.is_event, channels,
                           strong, n_pre, draws.n, draws.source, list(record.notes) + list(draws.notes), pga,
                           None if me is None else me.to_json())


def _expanded_residual(model: AffineModel, theta: np.ndarray, spec: list[tuple[Output, str]], nm: int,
                       y: np.ndarray, y_map: np.ndarray, cfg: PredictConfig) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the unmeasured acceleration outputs and the correction (k, N) they get: the
    residual of the measured channels recorded everywhere, expanded on the model's mode shapes
    (:mod:`.expansion`); none with ``unmeasured: model``."""
    N = y.shape[0]
    hidden = np.array([c for c in range(nm, len(spec)) if spec[c][1] == "acceleration"], dtype=int)
    full = [c for c in range(nm) if np.all(np.isfinite(y[:, c]))]
    if Unmeasured(cfg.unmeasured) == Unmeasured.MODEL or not full or not hidden.size:
        return np.zeros(0, dtype=int), np.zeros((0, N))
    rows = np.stack([o.row for o, _ in spec])
    if np.any(rows[full + hidden.tolist(), -1] != 0):  # a channel reading the ground: no mode shape
        return np.zeros(0, dtype=int), np.zeros((0, N))
    T = expansion_matrix(model, theta, rows[full, :-1], rows[hidden, :-1])
    return hidden, T @ (y[:, full].T - y_map[full])


def _peaks(Y: np.ndarray, s0: np.ndarray, rel2: np.ndarray, lms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per draw and output (B, o): the draw's peak |y| and the error standard deviation at the
    peak's time, ``sqrt(s0 + rel2 lms(t_peak))``. The peak's predictive draw is the peak plus one
    error draw there: the model error is correlated in time (a slightly wrong frequency shifts the
    whole peak cycle), so the peak moves by about one error standard deviation; the maximum over
    independent white-noise samples would move less and give intervals that are too narrow."""
    absY = np.abs(Y)
    t = np.argmax(absY, axis=2)  # (B, o)
    top = np.take_along_axis(absY, t[:, :, None], 2)[:, :, 0]
    o = np.arange(Y.shape[1])[None, :]
    return top, np.sqrt(s0[None, :] + rel2 * lms[o, t])


def channel_scores(y: np.ndarray, mean: np.ndarray, y_map: np.ndarray, y_nom: np.ndarray, lo: np.ndarray,
                   hi: np.ndarray, peak_ci: np.ndarray, strong: slice) -> dict[str, float | bool | None]:
    """NRMS of the predictive mean, the MAP and the nominal model; band coverage (all samples and
    the strong-motion part); the measured peak and whether it lies inside its interval."""
    ok = np.isfinite(y)
    inside = (y >= lo) & (y <= hi)
    s_ok = ok[strong]
    peak = float(np.max(np.abs(y[ok]))) if ok.any() else float("nan")
    return {
        "nrms_pct": nrms_pct(y, mean),
        "nrms_pct_map": nrms_pct(y, y_map),
        "nrms_pct_nominal": nrms_pct(y, y_nom),
        "coverage_95": float(np.mean(inside[ok])) if ok.any() else None,
        "coverage_95_strong": float(np.mean(inside[strong][s_ok])) if s_ok.any() else None,
        "peak_measured": peak,
        "peak_inside": bool(peak_ci[0] <= peak <= peak_ci[1]) if np.isfinite(peak) else None,
    }
