"""Pairing measured modes with model modes by MAC (not by order); the MAC is :mod:`shm_ros.core.modal`."""

from __future__ import annotations

import numpy as np

from shm_ros.core.modal import mac, mac_matrix

# Weight of the log-frequency distance next to MAC in the pairing score: shapes decide, frequency
# only separates shapes that look alike at few sensors.
FREQUENCY_WEIGHT = 0.5


def pairing_scores(f_obs: np.ndarray, phi_obs: np.ndarray | None,
                   f_model: np.ndarray, phi_model: np.ndarray | None) -> np.ndarray:
    """Score (B, m_o, m_m) of pairing each observed mode with each model mode; higher is better."""
    f_model = np.atleast_2d(f_model)
    with np.errstate(divide="ignore", invalid="ignore"):
        dist = np.abs(np.log(np.clip(f_model[:, None, :], 1e-12, None) / f_obs[None, :, None]))
    score = -FREQUENCY_WEIGHT * dist
    if phi_obs is not None and phi_model is not None:
        usable = ~np.any(np.isnan(phi_obs), axis=1)
        if usable.any():
            m = mac_matrix(np.nan_to_num(phi_obs), np.swapaxes(phi_model, -1, -2))
            score = score + np.where(usable[None, :, None], m, 0.0)
    return np.nan_to_num(score, nan=-np.inf)


def pair_modes(f_obs: np.ndarray, phi_obs: np.ndarray | None,
               f_model: np.ndarray, phi_model: np.ndarray | None) -> np.ndarray:
    """Model-mode index for every observed mode, per batch row: (B, m_o).

    Greedy one-to-one assignment on the score matrix, vectorised over the batch: take the best
    remaining (observed, model) pair, remove its row and column, repeat. For the few well separated
    modes of model updating this equals the optimal (Hungarian) assignment and costs m_o argmax
    passes instead of a Python loop over the batch.
    """
    score = pairing_scores(f_obs, phi_obs, f_model, phi_model).copy()
    B, m_o, m_m = score.shape
    if m_m < m_o:
        raise ValueError(f"model offers {m_m} modes for {m_o} observed modes")
    out = np.zeros((B, m_o), dtype=int)
    rows = np.arange(B)
    for _ in range(m_o):
        flat = np.argmax(score.reshape(B, -1), axis=1)
        i, j = np.divmod(flat, m_m)
        out[rows, i] = j
        score[rows, i, :] = -np.inf
        score[rows, :, j] = -np.inf
    return out


def pair_modes_optimal(f_obs: np.ndarray, phi_obs: np.ndarray | None,
                       f_model: np.ndarray, phi_model: np.ndarray | None) -> np.ndarray:
    """Optimal assignment (scipy's linear_sum_assignment) for a single model: (m_o,)."""
    from scipy.optimize import linear_sum_assignment

    score = pairing_scores(f_obs, phi_obs, f_model[None], None if phi_model is None else phi_model[None])[0]
    score = np.where(np.isfinite(score), score, -1e6)
    r, c = linear_sum_assignment(-score)
    out = np.zeros(len(f_obs), dtype=int)
    out[r] = c
    return out


def observations_from_estimates(estimates, f_ref: np.ndarray, phi_ref: np.ndarray, sensor_ids: list[str],
                                mac_min: float = 0.8, max_rel_shift: float = 0.3,
                                min_fraction: float = 0.5):
    """Per-window identified modes -> :class:`ModalObservations` numbered after reference modes.

    Used when updating starts from a recording without a tracked table: each window's modes are
    paired with the reference (nominal model) modes ``f_ref`` (m,), ``phi_ref`` (m, s) at
    ``sensor_ids`` by the same MAC-plus-frequency score as the likelihood (optimal assignment); a
    pair counts when MAC >= ``mac_min`` and the frequency is within ``max_rel_shift`` of the
    reference. Reference modes found in fewer than ``min_fraction`` of the windows are dropped;
    the rest are numbered 1, 2, ... by ascending reference frequency.
    """
    from .observations import ModalObservations

    n_w, m, s = len(estimates), len(f_ref), len(sensor_ids)
    F = np.full((n_w, m), np.nan)
    P = np.full((n_w, m, s), np.nan)
    D = np.full((n_w, m), np.nan)
    times, temps = np.zeros(n_w), np.full(n_w, np.nan)
    for w, e in enumerate(estimates):
        times[w] = e.start_ns * 1e-9
        if e.temperature_c is not None:
            temps[w] = e.temperature_c
        if not e.modes:
            continue
        cols = [e.sensor_ids.index(sid) if sid in e.sensor_ids else -1 for sid in sensor_ids]
        fw = np.array([md.frequency_hz for md in e.modes])
        pw = np.array([[md.mode_shape[c] if c >= 0 else np.nan for c in cols] for md in e.modes])
        ok = ~np.isnan(pw)
        pw0 = np.where(ok, pw, 0.0)
        score = pairing_scores(fw, pw0, f_ref[None], phi_ref.T[None])[0]  # (n_window_modes, m)
        from scipy.optimize import linear_sum_assignment

        r, c = linear_sum_assignment(-np.where(np.isfinite(score), score, -1e6))
        for i, k in zip(r, c, strict=True):
            macv = float(mac(pw0[i], phi_ref[k]))
            if macv >= mac_min and abs(fw[i] / f_ref[k] - 1.0) <= max_rel_shift:
                F[w, k] = fw[i]
                P[w, k] = pw[i]
                D[w, k] = e.modes[i].damping_ratio
    keep = np.flatnonzero(np.mean(np.isfinite(F), axis=0) >= min_fraction) if n_w else np.zeros(0, int)
    if keep.size == 0:
        raise ValueError("no identified mode matches a model mode in enough windows "
                         f"(MAC >= {mac_min}, frequency within {100 * max_rel_shift:.0f} %)")
    keep = keep[np.argsort(f_ref[keep])]
    notes = [f"reference mode {k + 1} ({f_ref[k]:.3f} Hz) found in {np.mean(np.isfinite(F[:, k])):.0%} "
             "of windows; dropped" for k in range(m) if k not in keep]
    return ModalObservations(times=times, mode_numbers=list(range(1, keep.size + 1)),
                             frequencies_hz=F[:, keep], shapes=P[:, keep], sensor_ids=list(sensor_ids),
                             damping=D[:, keep], covariates={"temperature_c": temps}, notes=notes)


def observations_for_model(model, estimates, sensor_ids: list[str] | None = None,
                           n_modes: int = 8, **pairing: float):
    """Identified windows -> :class:`ModalObservations` paired with the nominal model's modes.

    The sensors are those of the model that some estimate covers (or ``sensor_ids``); the
    reference is the nominal model's lowest ``n_modes`` modes at those sensors.
    """
    observed = [s for s in (sensor_ids or list(model.sensor_rows)) if s in model.sensor_rows]
    sensors = [s for s in observed if any(s in e.sensor_ids for e in estimates)]
    if not sensors:
        raise ValueError("no identified window covers a sensor of the model")
    sol = model.modes(None, min(n_modes, model.n_dof))
    phi = model.sensor_matrix(sensors) @ sol.shapes
    return observations_from_estimates(estimates, sol.frequencies_hz, phi.T, sensors, **pairing)
