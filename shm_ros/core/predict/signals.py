"""Record helpers of a prediction: event onset, baseline correction, strong motion, NRMS."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter1d

from shm_ros.core.response.signals import arias_fractions, strong_motion

from .config import Baseline, PredictConfig
from .record import EventRecord

__all__ = ["arias_fractions", "strong_motion", "pre_event_end", "baseline_correct", "local_mean_square",
           "nrms_pct"]


def pre_event_end(a: np.ndarray, fs: float, onset_arias: float, min_pre_event_s: float) -> int:
    """Samples before the event (where the input's Arias intensity reaches ``onset_arias``), at
    least ``min_pre_event_s`` seconds' worth (a record that starts with the event has no quiet part:
    its first samples stand in for one)."""
    x = np.asarray(a, dtype=float) - np.median(a)
    k = int(np.searchsorted(arias_fractions(x), onset_arias))
    return int(min(max(k, round(min_pre_event_s * fs), 2), x.size))


def baseline_correct(x: np.ndarray, n_pre: int, how: Baseline | str) -> np.ndarray:
    """``x`` (N,) or (N, c) minus the pre-event part's mean, or the line fitted to it."""
    x = np.asarray(x, dtype=float)
    pre = x[:n_pre]
    if Baseline(how) == Baseline.MEAN or n_pre < 3:
        return x - np.nanmean(pre, axis=0)
    t = np.arange(x.shape[0], dtype=float)
    tp = t[:n_pre]
    A = np.column_stack([np.ones(n_pre), tp])
    pre2 = pre.reshape(n_pre, -1)
    ok = np.all(np.isfinite(pre2), axis=1)
    coef, *_ = np.linalg.lstsq(A[ok], pre2[ok], rcond=None)
    trend = np.column_stack([np.ones_like(t), t]) @ coef
    return x - trend.reshape(x.shape)


def local_mean_square(y: np.ndarray, fs: float, window_s: float) -> np.ndarray:
    """Moving mean of ``y**2`` along the last axis over ``window_s`` seconds (centred)."""
    n = max(1, int(round(window_s * fs)))
    return uniform_filter1d(np.asarray(y, dtype=float) ** 2, n, axis=-1, mode="nearest")


def nrms_pct(measured: np.ndarray, predicted: np.ndarray) -> float:
    """||y - y_hat|| / ||y|| in percent over the finite samples of ``measured`` (the paper's eq. 28)."""
    ok = np.isfinite(measured)
    den = float(np.linalg.norm(measured[ok]))
    return float(100.0 * np.linalg.norm(measured[ok] - predicted[ok]) / den) if den > 0 else float("nan")


def prepare(record: EventRecord, cfg: PredictConfig) -> tuple[np.ndarray, np.ndarray, int]:
    """``(u, y, n_pre)``: the inputs (n_inputs, N) and outputs (N, c) of ``record`` baseline-corrected
    from the pre-event part, and that part's length (samples)."""
    n_pre = pre_event_end(record.inputs[0], record.fs, cfg.onset_arias, cfg.min_pre_event_s)
    u = baseline_correct(record.inputs.T, n_pre, cfg.baseline).T
    return u, baseline_correct(record.outputs, n_pre, cfg.baseline), n_pre
