"""Scores over events: the building paper's Table 3 and the JSON of docs/interfaces.md §7."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from shm_ros.core.models.base import AffineModel

from .predict import EventPrediction
from .signals import nrms_pct


def floor_channel(model: AffineModel, channel_ids: list[str], floor: int) -> str | None:
    """The measured sensor on ``floor`` (1-based) of a shear building, if any."""
    for cid in channel_ids:
        row = model.sensor_rows.get(cid)
        if row is not None and np.count_nonzero(row) == 1 and row[floor - 1] == 1.0:
            return cid
    return None


def integrated_drift(upper: np.ndarray, lower: np.ndarray, fs: float, highpass_hz: float = 0.2) -> np.ndarray:
    """A reference story drift from two measured floor accelerations, for scoring only: the
    difference integrated twice in the frequency domain above ``highpass_hz`` (never a prediction)."""
    a = np.nan_to_num(np.asarray(upper, float) - np.asarray(lower, float))
    n = a.size
    f = np.fft.rfftfreq(2 * n, 1.0 / fs)
    A = np.fft.rfft(a, 2 * n)
    w = 2 * np.pi * f
    D = np.zeros_like(A)
    keep = f > highpass_hz
    D[keep] = -A[keep] / w[keep] ** 2
    return np.fft.irfft(D, 2 * n)[:n]


def _highpass(x: np.ndarray, fs: float, hz: float = 0.2) -> np.ndarray:
    from scipy.signal import butter, sosfiltfilt  # here: scipy.signal's import is ~1 s of a node's start

    return sosfiltfilt(butter(4, hz / (fs / 2), btype="high", output="sos"), x)


def table3_row(model: AffineModel, pred: EventPrediction, floors: tuple[int, int] = (4, 8)) -> dict[str, Any]:
    """NRMS (%) of the floor accelerations at ``floors`` and of the top story's drift ratio, for the
    updated (predictive mean) and the nominal model; None where a floor is not measured."""
    ids = [c.name for c in pred.channels if c.measured]
    row: dict[str, Any] = {"window_id": pred.window_id}
    for k in floors:
        cid = floor_channel(model, ids, k)
        ch = pred.channel(cid) if cid else None
        row[f"accel_floor{k}"] = ch.scores["nrms_pct"] if ch else None
        row[f"accel_floor{k}_nominal"] = ch.scores["nrms_pct_nominal"] if ch else None
    n = model.n_dof
    top, below = floor_channel(model, ids, n), floor_channel(model, ids, n - 1) if n > 1 else None
    drift = next((c for c in pred.channels if c.name in (f"drift_ratio{n}", f"drift{n}")), None)
    row["drift_top"] = row["drift_top_nominal"] = None
    if top and below and drift is not None:
        y_top, y_below = pred.channel(top).values, pred.channel(below).values
        assert y_top is not None and y_below is not None  # measured channels carry their records
        ref = integrated_drift(y_top, y_below, pred.fs)
        if drift.quantity == "drift_ratio" and model.story_heights is not None:
            ref = ref / model.story_heights[n - 1]
        row["drift_top"] = nrms_pct(ref, _highpass(drift.mean, pred.fs))
        row["drift_top_nominal"] = nrms_pct(ref, _highpass(drift.nominal, pred.fs))
    return row


def format_table3(rows: list[dict[str, Any]]) -> str:
    """The rows as text: one line per event, updated (nominal) NRMS in %."""
    def cell(r: dict[str, Any], k: str) -> str:
        v, vn = r.get(k), r.get(f"{k}_nominal")
        return f"{'-':>18}" if v is None else f"{v:>8.1f} ({vn:>6.1f})"

    head = f"{'event':<14}{'accel floor 4':>18}{'accel floor 8':>18}{'drift ratio top':>18}"
    lines = ["NRMS % updated (nominal)", head]
    lines += [f"{r['window_id']:<14}{cell(r, 'accel_floor4')}{cell(r, 'accel_floor8')}{cell(r, 'drift_top')}"
              for r in rows]
    return "\n".join(lines)


def _num(v: Any) -> Any:
    if isinstance(v, float | np.floating):
        return None if not math.isfinite(float(v)) else float(v)
    return v


def event_json(pred: EventPrediction) -> dict[str, Any]:
    """One event of ``prediction.json`` (docs/interfaces.md §7)."""
    chans = []
    for c in pred.channels:
        d: dict[str, Any] = {"name": c.name, "quantity": c.quantity, "measured": c.measured,
                             "peak": _num(c.peak_mean), "peak_ci95": [_num(c.peak_ci[0]), _num(c.peak_ci[1])],
                             "uses_measured_records": c.measured or c.expanded,
                             "through": "measured" if c.measured else "shape expansion" if c.expanded else "model"}
        d.update({k: _num(v) for k, v in c.scores.items()})
        chans.append(d)
    return {"window_id": pred.window_id, "start_ns": pred.start_ns, "pga_m_s2": _num(pred.pga_m_s2),
            "is_event": pred.is_event, "n_draws": pred.n_draws, "error_model": pred.source,
            "input_pga_m_s2": _num(pred.input_pga_m_s2), "model_error": pred.model_error,
            "pre_event_s": pred.n_pre / pred.fs,
            "strong_motion_s": [pred.strong.start / pred.fs, pred.strong.stop / pred.fs],
            "channels": chans, "risk": pred.risk, "notes": list(pred.notes)}


def summary_json(preds: list[EventPrediction]) -> dict[str, Any]:
    """Medians over events and measured channels, pooled coverage and peak hits."""
    ms = [c.scores for p in preds for c in p.channels if c.measured]

    def med(k: str) -> float | None:
        v = [float(x) for s in ms if (x := s.get(k)) is not None and math.isfinite(float(x))]
        return float(np.median(v)) if v else None

    hits = [bool(s["peak_inside"]) for s in ms if s.get("peak_inside") is not None]
    return {"nrms_pct_median": med("nrms_pct"), "nrms_pct_nominal_median": med("nrms_pct_nominal"),
            "coverage_95_median": med("coverage_95"), "coverage_95_strong_median": med("coverage_95_strong"),
            "peaks_inside_fraction": float(np.mean(hits)) if hits else None, "n_events": len(preds),
            "events_outside_calibration": [p.window_id for p in preds if p.risk and p.risk["outside_calibration"]]}
