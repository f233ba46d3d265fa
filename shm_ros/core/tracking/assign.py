"""One window's modes onto the tracked modes: identity by shape first.

The optimal one-to-one assignment (``scipy.optimize.linear_sum_assignment``) on the cost

    (1 - MAC) / (1 - mac_min)  +  freq_weight * |f - f_pred| / f_pred / gate

where both terms must be <= 1 (gated). The shape term leads: two modes whose frequencies cross keep
their identities as long as their shapes differ more than the identification scatter. ``f_pred``
is the frequency the tracker expects (the environmental model's prediction plus the recent offset,
or the drift-following reference before the model is fitted); ``gate`` is relative, ``freq_tol``
widened by the predicted shift from the reference, by the mode's spread in the reference period
and by consecutive misses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from shm_ros.core.tracking.config import TrackingConfig
from shm_ros.core.tracking.shapes import mac_table

BIG = 1e6


@dataclass
class Assignment:
    index: np.ndarray  # (n_tracked,) index of the window's mode, -1 = not found
    mac: np.ndarray  # (n_tracked,) MAC with the reference shape, NaN = not found
    unassigned: np.ndarray  # indices of the window's modes left over


def gates(cfg: TrackingConfig, predicted: np.ndarray, reference: np.ndarray, misses: np.ndarray,
          spread: np.ndarray | None = None) -> np.ndarray:
    """Relative frequency gate of each tracked mode: ``freq_tol`` (or twice the mode's spread in
    the reference period, when larger: an event catalogue's amplitude softening), widened by the
    predicted shift from the reference and by consecutive misses, at most ``max_freq_gate``."""
    with np.errstate(invalid="ignore", divide="ignore"):
        shift = np.nan_to_num(np.abs(predicted - reference) / reference)
    base = cfg.freq_tol if spread is None else np.maximum(cfg.freq_tol, 2.0 * spread)
    g = base * (1.0 + 0.5 * np.minimum(misses, 6)) + shift
    return np.minimum(g, cfg.max_freq_gate)


def assign(freq: np.ndarray, shapes: np.ndarray, predicted: np.ndarray, gate: np.ndarray,
           ref_shapes: np.ndarray, cfg: TrackingConfig) -> Assignment:
    n_t = predicted.size
    idx = np.full(n_t, -1)
    macs = np.full(n_t, np.nan)
    if freq.size == 0 or n_t == 0:
        return Assignment(idx, macs, np.arange(freq.size))
    mac = mac_table(shapes, ref_shapes)
    with np.errstate(invalid="ignore", divide="ignore"):
        df = np.abs(freq[:, None] - predicted[None, :]) / predicted[None, :] / gate[None, :]
    dm = (1.0 - mac) / (1.0 - cfg.mac_min)
    ok = (df <= 1.0) & (dm <= 1.0)
    cost = np.where(ok, dm + cfg.freq_weight * np.nan_to_num(df, nan=BIG), BIG)
    rows, cols = linear_sum_assignment(cost)
    keep = ok[rows, cols]
    rows, cols = rows[keep], cols[keep]
    idx[cols] = rows
    macs[cols] = mac[rows, cols]
    return Assignment(idx, macs, np.setdiff1d(np.arange(freq.size), rows))
