"""Pairing observed modes with model modes, once, behind a gate.

Updating pairs the data's modes with the model's once - at the prior mean, and again once at the MAP
(:func:`shm_ros.core.bayes.update.update`) - never per theta inside the likelihood: a pairing that
is redone for every theta lets the sampler buy a good fit by pairing an observed mode with whatever
model mode a distorted theta brings near it (a lateral mode of a bridge with a vertical bending mode
of a plane girder model, bought with an absurd bearing stiffness).

:func:`gated_pairing` is the one-to-one (Hungarian) assignment on the cost
``|ln(f_model / f_obs)| / ln(1 + frequency_gate) + (1 - MAC) / (1 - mac_gate)`` (the MAC term only
where the observed mode has a shape): a 20 % gate admits model frequencies from f_obs / 1.2 to
1.2 f_obs. A pair beyond either gate is not made: that observed mode is
*unmodelled* - left out of the likelihood and reported with its nearest model mode and the reason
(docs/interfaces.md §6 ``unmodelled_modes``). The default frequency gate follows the prior width
(:func:`automatic_frequency_gate`). The same gate pairs per-window estimates with the reference
model when the data come from a recording (:func:`observations_from_estimates`).

The ungated scores (:func:`pairing_scores`, :func:`pair_modes`) remain for diagnostics and fit
reports at a single theta; the MAC itself is :mod:`shm_ros.core.modal`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from shm_ros.core.modal import mac_matrix
from shm_ros.core.mode_pairing import (  # noqa: F401  (the pairing's results, re-exported)
    DEFAULT_MAC_GATE,
    GATE_RANGE,
    ModePairing,
    PairingGate,
    UnmodelledMode,
    automatic_frequency_gate,
)

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
    score = pairing_scores(f_obs, phi_obs, f_model[None], None if phi_model is None else phi_model[None])[0]
    score = np.where(np.isfinite(score), score, -1e6)
    r, c = linear_sum_assignment(-score)
    out = np.zeros(len(f_obs), dtype=int)
    out[r] = c
    return out



# -- the gate ----------------------------------------------------------------------------------------

_OUT = 1e6  # cost of a pair beyond a gate: the assignment makes as many in-gate pairs as it can


def _usable_shapes(phi_obs: np.ndarray | None, phi_model: np.ndarray | None, m_o: int) -> np.ndarray:
    if phi_obs is None or phi_model is None or phi_model.shape[0] == 0:
        return np.zeros(m_o, dtype=bool)
    return np.all(np.isfinite(phi_obs), axis=1) & (np.sum(np.nan_to_num(phi_obs) ** 2, axis=1) > 0)


def gate_costs(f_obs: np.ndarray, phi_obs: np.ndarray | None, f_model: np.ndarray,
               phi_model: np.ndarray | None, gate: PairingGate
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cost (m_o, m_m), log-frequency distance, MAC (NaN where no shape) and the in-gate mask.

    ``phi_obs`` (m_o, s) and ``phi_model`` (s, m_m) at the same sensors (or None).
    """
    f_obs = np.asarray(f_obs, dtype=float)
    f_model = np.asarray(f_model, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        dist = np.abs(np.log(np.clip(f_model[None, :], 1e-300, None) / f_obs[:, None]))
    dist = np.where(np.isfinite(dist), dist, np.inf)
    ok = dist <= math.log1p(gate.frequency)
    cost = dist / math.log1p(gate.frequency)
    macs = np.full(dist.shape, np.nan)
    usable = _usable_shapes(phi_obs, phi_model, len(f_obs))
    if usable.any():
        assert phi_obs is not None and phi_model is not None  # usable implies both
        macs[usable] = mac_matrix(phi_obs[usable], phi_model.T)
        m_ok = np.where(usable[:, None], macs >= gate.mac, True)
        ok &= m_ok
        cost = cost + np.where(usable[:, None], (1.0 - np.nan_to_num(macs)) / (1.0 - gate.mac), 0.0)
    return cost, dist, macs, ok


def gated_pairing(f_obs: np.ndarray, phi_obs: np.ndarray | None, f_model: np.ndarray,
                  phi_model: np.ndarray | None, gate: PairingGate,
                  mode_numbers: Sequence[int | None] | None = None) -> ModePairing:
    """One-to-one pairing of observed modes with one model's modes behind ``gate``.

    ``f_obs`` (m_o,), ``phi_obs`` (m_o, s) or None, ``f_model`` (m_m,) ascending, ``phi_model``
    (s, m_m) or None. Pairs beyond a gate are never made (their cost is prohibitive, so the
    assignment first makes as many in-gate pairs as it can, then the cheapest such set).
    """
    m_o = len(f_obs)
    numbers = list(mode_numbers) if mode_numbers is not None else list(range(1, m_o + 1))
    cost, dist, macs, ok = gate_costs(f_obs, phi_obs, f_model, phi_model, gate)
    finite = np.where(ok, cost, _OUT)
    finite = np.where(np.isfinite(finite), finite, _OUT)
    rows, cols = linear_sum_assignment(finite) if finite.size else (np.zeros(0, int), np.zeros(0, int))
    paired = {int(r): int(c) for r, c in zip(rows, cols, strict=True) if ok[r, c]}
    unmodelled = []
    for i in range(m_o):
        if i in paired:
            continue
        in_freq = dist[i] <= math.log1p(gate.frequency)
        if not in_freq.any():
            reason, j = "frequency", int(np.argmin(dist[i]))
        elif not ok[i].any():
            reason = "mac"
            j = int(np.flatnonzero(in_freq)[np.argmax(np.nan_to_num(macs[i, in_freq]))])
        else:
            reason = "one-to-one"
            j = int(np.flatnonzero(ok[i])[np.argmin(cost[i, ok[i]])])
        unmodelled.append(UnmodelledMode(
            numbers[i], float(f_obs[i]), j + 1, float(f_model[j]), float(f_model[j] / f_obs[i]),
            None if not np.isfinite(macs[i, j]) else float(macs[i, j]), reason))
    keep = np.array(sorted(paired), dtype=int)
    return ModePairing(keep, np.array([paired[i] for i in keep], dtype=int), unmodelled, gate)


def pair_with_model(predictor: Any, f_obs: np.ndarray, phi_obs: np.ndarray | None, theta: np.ndarray,
                    gate: PairingGate, mode_numbers: Sequence[int] | None = None) -> ModePairing:
    """:func:`gated_pairing` against a predictor's modes at one ``theta``."""
    f, phi = predictor(np.atleast_2d(np.asarray(theta, dtype=float)))
    shapes = phi[0] if (phi_obs is not None and phi.shape[1] > 0) else None
    return gated_pairing(f_obs, phi_obs, f[0], shapes, gate, mode_numbers)


def select_modes(obs, keep: np.ndarray):
    """The same observations restricted to the modes ``keep`` (indices)."""
    from dataclasses import replace

    keep = np.asarray(keep, dtype=int)
    return replace(obs, mode_numbers=[obs.mode_numbers[k] for k in keep],
                   frequencies_hz=obs.frequencies_hz[:, keep],
                   shapes=None if obs.shapes is None else obs.shapes[:, keep],
                   damping=None if obs.damping is None else obs.damping[:, keep],
                   notes=list(obs.notes), unmodelled_modes=list(obs.unmodelled_modes))


# -- recordings: per-window estimates ----------------------------------------------------------------

def observations_from_estimates(estimates, f_ref: np.ndarray, phi_ref: np.ndarray, sensor_ids: list[str],
                                gate: PairingGate | None = None, min_fraction: float = 0.5,
                                cluster_tolerance: float = 0.03):
    """Per-window identified modes -> :class:`ModalObservations` numbered after reference modes.

    Used when updating starts from a recording without a tracked table: each window's modes are
    paired one-to-one with the reference (nominal model) modes ``f_ref`` (m,), ``phi_ref`` (m, s) at
    ``sensor_ids`` by :func:`gated_pairing` (the updating's gate). Reference modes found in fewer
    than ``min_fraction`` of the windows are dropped; the rest are numbered 1, 2, ... by ascending
    reference frequency. Identified modes that pair with no reference mode are grouped by frequency
    (neighbours within ``cluster_tolerance``); a group present in at least ``min_fraction`` of the
    windows is an unmodelled mode (``unmodelled_modes`` of the result, and a note).
    """
    from shm_ros.core.observations import ModalObservations

    gate = gate or PairingGate()
    n_w, m, s = len(estimates), len(f_ref), len(sensor_ids)
    F = np.full((n_w, m), np.nan)
    P = np.full((n_w, m, s), np.nan)
    D = np.full((n_w, m), np.nan)
    times, temps = np.zeros(n_w), np.full(n_w, np.nan)
    strays: list[tuple[int, UnmodelledMode]] = []
    for w, e in enumerate(estimates):
        times[w] = e.start_ns * 1e-9
        if e.temperature_c is not None:
            temps[w] = e.temperature_c
        if not e.modes:
            continue
        cols = [e.sensor_ids.index(sid) if sid in e.sensor_ids else -1 for sid in sensor_ids]
        fw = np.array([md.frequency_hz for md in e.modes])
        pw = np.array([[md.mode_shape[c] if c >= 0 else np.nan for c in cols] for md in e.modes])
        # missing sensors count as zero in the MAC (as before): a shape is usable when any is present
        pw0 = np.where(np.isnan(pw), 0.0, pw)
        pw0[np.all(np.isnan(pw), axis=1)] = np.nan
        pairing = gated_pairing(fw, pw0, f_ref, phi_ref.T, gate, [None] * len(fw))
        for i, k in zip(pairing.observed, pairing.model_index, strict=True):
            F[w, k] = fw[i]
            P[w, k] = pw[i]
            D[w, k] = e.modes[i].damping_ratio
        strays += [(w, u) for u in pairing.unmodelled]
    keep = np.flatnonzero(np.mean(np.isfinite(F), axis=0) >= min_fraction) if n_w else np.zeros(0, int)
    if keep.size == 0:
        raise ValueError("no identified mode matches a model mode in enough windows "
                         f"(MAC >= {gate.mac}, frequency within {100 * gate.frequency:.0f} %)")
    keep = keep[np.argsort(f_ref[keep])]
    notes = [f"reference mode {k + 1} ({f_ref[k]:.3f} Hz) found in {np.mean(np.isfinite(F[:, k])):.0%} "
             "of windows; dropped" for k in range(m) if k not in keep]
    unmodelled = _recurring(strays, n_w, min_fraction, cluster_tolerance)
    notes += [u.message(gate) for u in unmodelled]
    return ModalObservations(times=times, mode_numbers=list(range(1, keep.size + 1)),
                             frequencies_hz=F[:, keep], shapes=P[:, keep], sensor_ids=list(sensor_ids),
                             damping=D[:, keep], covariates={"temperature_c": temps}, notes=notes,
                             unmodelled_modes=[u.to_dict() for u in unmodelled])


def _recurring(strays: list[tuple[int, UnmodelledMode]], n_windows: int, min_fraction: float,
               tolerance: float) -> list[UnmodelledMode]:
    """Unpaired per-window modes grouped by frequency; the groups seen in enough windows."""
    if not strays or n_windows == 0:
        return []
    strays = sorted(strays, key=lambda t: t[1].frequency_hz)
    groups: list[list[tuple[int, UnmodelledMode]]] = [[strays[0]]]
    for item in strays[1:]:
        if item[1].frequency_hz <= groups[-1][-1][1].frequency_hz * (1.0 + tolerance):
            groups[-1].append(item)
        else:
            groups.append([item])
    out = []
    for g in groups:
        frac = len({w for w, _ in g}) / n_windows
        if frac < min_fraction:
            continue
        f = float(np.median([u.frequency_hz for _, u in g]))
        rep = min((u for _, u in g), key=lambda u: abs(u.frequency_hz - f))
        reasons = [u.reason for _, u in g]
        out.append(UnmodelledMode(None, f, rep.nearest_model_mode, rep.nearest_model_frequency_hz,
                                  float(rep.nearest_model_frequency_hz / f), rep.mac,
                                  max(set(reasons), key=reasons.count), min(frac, 1.0)))
    return out


def observations_for_model(model, estimates, sensor_ids: list[str] | None = None,
                           n_modes: int = 8, theta: np.ndarray | None = None,
                           gate: PairingGate | None = None, **options: float):
    """Identified windows -> :class:`ModalObservations` paired with the model's modes at ``theta``.

    The sensors are those of the model that some estimate covers (or ``sensor_ids``); the
    reference is the model's lowest ``n_modes`` modes at those sensors at ``theta`` (default: the
    nominal model; updating passes the prior mean and its gate,
    :func:`shm_ros.core.bayes.update.pairing_reference`).
    """
    observed = model.observed_sensors(sensor_ids)
    sensors = [s for s in observed if any(s in e.sensor_ids for e in estimates)]
    if not sensors:
        raise ValueError("no identified window covers a sensor of the model")
    sol = model.modes(theta, min(n_modes, model.n_dof))
    phi = model.sensor_matrix(sensors) @ sol.shapes
    return observations_from_estimates(estimates, sol.frequencies_hz, phi.T, sensors, gate, **options)
