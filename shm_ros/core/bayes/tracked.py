"""Tracked modes -> the updating's modal data: one column per tracked mode, identities kept.

Updating from a recording goes windows -> modal estimates -> tracked modes
(:mod:`shm_ros.core.tracking`: identity by shape first, across crossings, misses and spurious
modes) -> :class:`ModalObservations` -> :func:`shm_ros.core.bayes.update.update`, which pairs the
tracked modes with the model's modes once (at the prior mean, behind the gate; once more at the
MAP). A tracked mode that pairs with no model mode is reported there as unmodelled. Pairing every
window's modes with the model instead (``pairing.observations_for_model``) trusts the prior-mean
model to tell a window's modes apart; a spurious mode near a model frequency in a window where the
true mode was missed is then taken for it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from shm_ros.core.observations import ModalObservations


def observations_from_rows(rows: Sequence[Any], sensor_ids: Sequence[str] | None = None) -> ModalObservations:
    """Tracked rows (:class:`shm_ros.core.tracking.TrackedRow` or alike: ``start_ns``,
    ``mode_numbers``, ``frequencies_hz``, ``damping``, ``sensor_ids``, ``shapes`` (modes, sensors),
    ``covariates``) -> one column per tracked mode, one row per window in time order.

    A mode born after the first rows is NaN before its birth; a window's row repeated (the same
    ``window_id``) counts once, the last one. ``sensor_ids`` (default: every sensor of the rows)
    selects and orders the shape components (NaN where a row lacks the sensor).
    """
    latest = {getattr(r, "window_id", i): r for i, r in enumerate(rows)}
    ordered = sorted(latest.values(), key=lambda r: int(r.start_ns))
    if not ordered:
        raise ValueError("no tracked rows")
    numbers: list[int] = []
    sensors: list[str] = list(sensor_ids) if sensor_ids is not None else []
    for r in ordered:
        numbers += [int(k) for k in r.mode_numbers if int(k) not in numbers]
        if sensor_ids is None:
            sensors += [s for s in r.sensor_ids if s not in sensors]
    numbers.sort()
    col = {n: k for k, n in enumerate(numbers)}
    n_w, n_m, n_s = len(ordered), len(numbers), len(sensors)
    freq, damp = np.full((n_w, n_m), np.nan), np.full((n_w, n_m), np.nan)
    shapes = np.full((n_w, n_m, n_s), np.nan)
    covs: list[str] = []
    for w, r in enumerate(ordered):
        cols = [col[int(k)] for k in r.mode_numbers]
        freq[w, cols] = np.asarray(r.frequencies_hz, dtype=float)
        damp[w, cols] = np.asarray(r.damping, dtype=float)
        s = np.asarray(r.shapes, dtype=float).reshape(len(cols), len(r.sensor_ids))
        have = [(j, r.sensor_ids.index(sid)) for j, sid in enumerate(sensors) if sid in r.sensor_ids]
        if have:
            dst, src = (list(t) for t in zip(*have, strict=True))
            shapes[w][np.ix_(cols, dst)] = s[:, src]
        covs += [c for c in r.covariates if c not in covs]
    freq[~(freq > 0)] = np.nan  # a zero or negative frequency is no frequency
    cov = {c: np.array([float(r.covariates.get(c, np.nan)) for r in ordered]) for c in covs}
    return ModalObservations(times=np.array([int(r.start_ns) * 1e-9 for r in ordered]), mode_numbers=numbers,
                             frequencies_hz=freq, shapes=shapes if n_s else None, sensor_ids=sensors,
                             damping=damp, covariates=cov, time_kind="iso")


def at_sensors(obs: ModalObservations, sensor_ids: Sequence[str]) -> ModalObservations:
    """The same table with shape components at ``sensor_ids`` only (e.g. the model's sensors; a
    tracked table may carry others, such as a ground input sensor)."""
    from dataclasses import replace

    keep = [s for s in sensor_ids if s in obs.sensor_ids]
    if obs.shapes is None or not keep:
        return replace(obs, shapes=None, sensor_ids=[], notes=list(obs.notes))
    idx = [obs.sensor_ids.index(s) for s in keep]
    return replace(obs, shapes=obs.shapes[:, :, idx], sensor_ids=keep, notes=list(obs.notes))


def observations_from_tracking(estimates: Sequence[Any], sensor_ids: Sequence[str],
                               config: Any = None, structure: Any = None) -> ModalObservations:
    """Per-window modal estimates -> tracked (``shm_ros.core.tracking.track``, as ``shm-ros track``)
    -> one column per tracked mode, shapes at ``sensor_ids``. The tracker's notes (modes born, ...)
    become the table's notes."""
    from shm_ros.core.tracking import TrackingConfig, track

    res = track(list(estimates), config or TrackingConfig(), structure=structure)
    obs = at_sensors(res.observations, sensor_ids)
    found = np.mean(np.isfinite(obs.frequencies_hz), axis=0)
    obs.notes = [f"{obs.n_windows} windows tracked: "
                 + ", ".join(f"mode {n} at {f:.3f} Hz in {p:.0%} of windows" for n, f, p in
                             zip(obs.mode_numbers, obs.mean_frequencies(), found, strict=True))
                 + (f"; {res.unassigned} identified modes matched no tracked mode" if res.unassigned else ""),
                 *[n for n in res.notes if not n.startswith("no covariate")]]
    return obs
