"""Mode shapes on the tracker's sensor list (windows may lose channels; MAC on common sensors)."""

from __future__ import annotations

import numpy as np

from shm_ros.core.modal import mac as modal_mac
from shm_ros.core.modal import sign_aligned
from shm_ros.core.types import ModalEstimate


def shapes_on(est: ModalEstimate, sensors: list[str]) -> np.ndarray:
    """(n_modes, n_sensors) shapes of one window on ``sensors`` (NaN where absent)."""
    out = np.full((len(est.modes), len(sensors)), np.nan)
    col = {s: j for j, s in enumerate(sensors)}
    idx = [col[s] for s in est.sensor_ids]
    for k, m in enumerate(est.modes):
        out[k, idx] = np.asarray(m.mode_shape, dtype=float)
    return out


def mac_table(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """MAC of every row of ``a`` against every row of ``b`` on their common finite sensors.

    Two common sensors at least: one sensor of several in common says nothing about the shapes
    (0). A structure with a single sensor has shapes that say nothing at all: their MAC is 1 and
    the frequencies alone tell the modes apart."""
    if a.shape[0] == 0 or b.shape[0] == 0:
        return np.zeros((a.shape[0], b.shape[0]))
    return np.asarray(modal_mac(a[:, None, :], b[None, :, :], min_common=min(2, a.shape[-1])))


def aligned(shape: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """``shape`` with the sign that agrees with ``ref`` on their common sensors."""
    return sign_aligned(shape, ref)


def widen(shapes: np.ndarray, n_sensors: int) -> np.ndarray:
    """Pad the last axis with NaN to ``n_sensors`` (a sensor seen for the first time)."""
    if shapes.shape[-1] >= n_sensors:
        return shapes
    pad = np.full((*shapes.shape[:-1], n_sensors - shapes.shape[-1]), np.nan)
    return np.concatenate([shapes, pad], axis=-1)
