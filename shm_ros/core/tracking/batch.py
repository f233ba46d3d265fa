"""``track(estimates, config)``: the tracker run over a whole campaign -> the tracked-modes table.

The training period is the first ``training_fraction`` of the windows; the reference period the
first ``reference_windows`` (all of them when the record is shorter: an event catalogue of a few
earthquakes years apart is tracked too). Window for window the result equals the node's.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from shm_ros.core.observations import ModalObservations
from shm_ros.core.tracking.config import TrackingConfig
from shm_ros.core.tracking.environment import EnvironmentalFit
from shm_ros.core.tracking.novelty import alarm_episodes
from shm_ros.core.tracking.online import TrackedRow, Tracker
from shm_ros.core.tracking.reference import ReferenceMode
from shm_ros.core.types import ModalEstimate
from shm_ros.errors import InputError


class NoTrackedModes(InputError):
    """No mode is found in enough of the reference windows to be tracked (too few or too different
    windows for the settings): a caller with a structure file may match the modes to its model."""

if TYPE_CHECKING:
    from shm_ros.core.structure import StructureSpec


@dataclass
class TrackingResult:
    observations: ModalObservations  # the tracked-modes table (docs/interfaces.md §4)
    reference: list[ReferenceMode]
    mac_to_reference: np.ndarray  # (n_windows, n_modes), NaN = not found
    environment: list[EnvironmentalFit]
    novelty_score: np.ndarray  # (n_windows,), NaN before the chart starts
    novelty_threshold: float
    novelty_alarm: np.ndarray  # (n_windows,) bool
    n_training: int
    unassigned: int  # identified modes that matched no tracked mode (spurious or new)
    # main covariate outside the range seen in training: the environmental model extrapolates there
    outside_training: np.ndarray | None = None
    window_ids: list[str] = field(default_factory=list)  # in time order, as the table's rows
    notes: list[str] = field(default_factory=list)
    normalised_hz: np.ndarray | None = None  # (n_windows, n_modes) at the training mean conditions
    alarm_modes: list[list[int]] = field(default_factory=list)  # per window
    episodes: list[tuple[int, int]] = field(default_factory=list)  # (first, last) alarm windows

    def normalised_observations(self) -> ModalObservations:
        """The table with normalised frequencies (same columns; docs/interfaces.md §4)."""
        o = self.observations
        f = self.normalised_hz if self.normalised_hz is not None else np.full_like(o.frequencies_hz, np.nan)
        return ModalObservations(o.times, list(o.mode_numbers), f, o.shapes, list(o.sensor_ids), o.damping,
                                 dict(o.covariates), [], o.time_kind)


def rows_to_result(rows: list[TrackedRow], tracker: Tracker, n_train: int) -> TrackingResult:
    """Assemble the table from the tracker's rows (modes born later are NaN before their birth)."""
    numbers = tracker.numbers
    sensors = list(tracker.sensors)
    n_w, n_m, n_s = len(rows), len(numbers), len(sensors)
    freq, damp, macs, norm = (np.full((n_w, n_m), np.nan) for _ in range(4))
    shapes = np.full((n_w, n_m, n_s), np.nan)
    for w, r in enumerate(rows):
        k, s = len(r.mode_numbers), len(r.sensor_ids)
        freq[w, :k], damp[w, :k], macs[w, :k] = r.frequencies_hz, r.damping, r.macs
        if r.normalised_hz.size:
            norm[w, :k] = r.normalised_hz
        shapes[w, :k, :s] = r.shapes
    names: list[str] = []
    for r in rows:
        names += [c for c in r.covariates if c not in names]
    cov = {c: np.array([r.covariates.get(c, np.nan) for r in rows]) for c in names}
    times = np.array([r.start_ns / 1e9 for r in rows])
    obs = ModalObservations(times=times, mode_numbers=numbers, frequencies_hz=freq, shapes=shapes,
                            sensor_ids=sensors, damping=damp, covariates=cov, time_kind="iso")
    score = np.array([r.novelty_score for r in rows])
    alarm = np.array([r.novelty_alarm for r in rows], bool)
    notes = list(tracker.notes)
    main = tracker.config.covariate
    outside = np.zeros(n_w, bool)
    x = cov.get(main)
    if x is not None and np.isfinite(x[:n_train]).any():
        lo, hi = np.nanmin(x[:n_train]), np.nanmax(x[:n_train])
        margin = 0.05 * (hi - lo)
        outside = np.isfinite(x) & ((x < lo - margin) | (x > hi + margin))
        if np.any(alarm & outside):
            notes.append(f"{int(np.sum(alarm & outside))} of {int(alarm.sum())} novelty alarms are at {main} "
                         f"outside the training range [{lo:.3g}, {hi:.3g}]")
    if x is None:
        notes.append(f"no covariate {main!r} measured")
    return TrackingResult(obs, tracker.reference, macs, tracker.environment, score, tracker.threshold, alarm,
                          min(n_train, n_w), tracker.unassigned, outside, [r.window_id for r in rows], notes,
                          norm, [r.alarm_modes for r in rows], alarm_episodes(alarm))


def track(estimates: list[ModalEstimate], config: TrackingConfig | None = None,
          structure: StructureSpec | None = None) -> TrackingResult:
    """Tracked modes of ``estimates`` (sorted by time here; see the module docstring)."""
    cfg = config or TrackingConfig()
    estimates = sorted(estimates, key=lambda e: e.start_ns)
    if not estimates:
        raise ValueError("track: no modal estimates")
    n_train = max(3, int(np.ceil(cfg.training_fraction * len(estimates))))
    tracker = Tracker(cfg, training_windows=n_train, structure=structure)
    rows: list[TrackedRow] = []
    for e in estimates:
        rows += tracker.add(e)
    rows += tracker.flush()
    if not tracker.ready:
        raise NoTrackedModes(f"track: no mode is found in {cfg.min_presence:.0%} of the first "
                         f"{min(cfg.reference_windows, len(estimates))} windows")
    return rows_to_result(rows, tracker, n_train)
