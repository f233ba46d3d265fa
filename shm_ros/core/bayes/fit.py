"""How well a model at one theta reproduces tracked modal data (frequency RMSE, MAC).

Definitions (also in docs/updating.md):

* per-mode frequency RMSE = root mean square over the windows of the relative error
  ``(f_obs - f_model) / f_obs`` (reported in percent in ``frequency_rmse_pct``, as a fraction in the
  study table);
* per-mode MAC = mean over the windows of MAC(observed shape, model shape at the sensors);
* overall: RMS over every (window, mode) value, and the mean of the per-mode MACs.

The model mode of every data mode is the updating's fixed pairing when given (``pairing``), else the
optimal assignment at this theta (see :mod:`.pairing`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from shm_ros.core.modal import mac
from shm_ros.core.observations import ModalObservations

from .forward import ModalPredictor
from .pairing import pair_modes_optimal


def modal_fit(predictor: ModalPredictor, obs: ModalObservations, theta: np.ndarray,
              pairing: np.ndarray | None = None) -> dict:
    f_model, phi_model = predictor(np.atleast_2d(theta))
    f_ref = obs.mean_frequencies()
    shapes = obs.has_shapes and list(predictor.sensor_ids) == list(obs.sensor_ids)
    phi_ref = obs.reference_shapes() if shapes else None
    if pairing is not None:
        idx = np.asarray(pairing, dtype=int)
    else:
        usable = phi_ref is not None and bool(np.all(np.isfinite(phi_ref)))
        idx = pair_modes_optimal(f_ref, phi_ref if usable else None, f_model[0],
                                 phi_model[0] if usable else None)
    fp = f_model[0, idx]
    rel = (obs.frequencies_hz - fp[None]) / obs.frequencies_hz
    per_mode_rmse = np.sqrt(np.nanmean(rel**2, axis=0))
    modes: list[dict[str, Any]] = []
    out: dict[str, Any] = {
        "frequency_rmse_pct": float(100 * np.sqrt(np.nanmean(rel**2))),
        "modes": modes,
    }
    macs = np.full(obs.n_modes, np.nan)
    if shapes:
        assert obs.shapes is not None
        for k in range(obs.n_modes):
            rows = obs.shapes[:, k, :]
            ok = np.all(np.isfinite(rows), axis=1)
            if ok.any():
                macs[k] = float(np.mean(mac(rows[ok], phi_model[0, :, idx[k]][None])))
        out["mac_mean"] = float(np.nanmean(macs)) if np.any(np.isfinite(macs)) else None
    else:
        out["mac_mean"] = None
    for k, mnum in enumerate(obs.mode_numbers):
        modes.append({
            "mode": int(mnum),
            "frequency_obs_hz": float(f_ref[k]),
            "frequency_model_hz": float(fp[k]),
            "model_mode_index": int(idx[k]) + 1,
            "frequency_rmse": float(per_mode_rmse[k]),
            "mac": None if not np.isfinite(macs[k]) else float(macs[k]),
        })
    return out
