"""Where each roving sensor is at each sample, and the setups cut where every one of them dwells.

:func:`sensor_track` composes the tf chain from the structure's frame to a roving sensor's frame at
every sample time (:class:`~shm_ros.core.roving.transforms.TransformBuffer`; the structure file's
``mount`` stands in for a missing ``/tf_static``), and rotates the sensor's
``linear_acceleration`` into the structure's frame (a tilted mount, a perched drone). Missing
stretches of the chain are errors naming the frames, never a default position.

:func:`cut_setups` first filters each position track (a running median over ``filter_s``: it removes
localisation noise and spikes, and moves a step such as a map -> odom jump by at most half the
window), then gives every sample the measurement point within ``tolerance`` of the filtered
position (none: moving or off the points). A setup is a stretch of at least ``min_dwell_s`` during
which every roving sensor stays at one point; a stretch with no transform splits it into segments of
the same setup and is reported. Samples at no point are counted and left out.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.ndimage as ndi

from shm_ros.core.roving.transforms import Gap, TransformBuffer, TransformError
from shm_ros.core.structure import MeasurementPoint, RovingSensorSpec
from shm_ros.core.timeutil import ns_to_iso

__all__ = ["SensorTrack", "Setup", "SetupCut", "sensor_track", "cut_setups", "DEFAULT_TOLERANCE_M",
           "DEFAULT_MIN_DWELL_S", "DEFAULT_FILTER_S"]

DEFAULT_TOLERANCE_M = 0.05
DEFAULT_MIN_DWELL_S = 20.0
DEFAULT_FILTER_S = 1.0


@dataclass
class SensorTrack:
    """A roving sensor's positions (n, 3) in the structure's frame at the sample times, its
    accelerations rotated into that frame (n, 3; None if not given), and where the chain is missing."""

    sensor: str
    times_ns: np.ndarray
    position: np.ndarray
    acceleration: np.ndarray | None
    valid: np.ndarray
    gaps: list[Gap]
    tf_period_s: float = 0.0  # the chain's longest median period (the setups' edge guard)


def sensor_track(buffer: TransformBuffer, structure_frame: str, sensor: RovingSensorSpec, times_ns: np.ndarray,
                 acceleration: np.ndarray | None = None) -> SensorTrack:
    """Positions of ``sensor`` (and its ``acceleration`` (n, 3) in the structure's frame) at ``times_ns``."""
    times = np.asarray(times_ns, dtype=np.int64)
    if sensor.frame not in buffer.frames:
        if sensor.mount is None:
            raise TransformError(
                f"roving sensor {sensor.id!r}: no transform to its frame {sensor.frame!r} (no /tf_static for it, "
                "and the structure file gives no mount for it)")
        m = sensor.mount
        buffer.set_transform(m.parent, sensor.frame, 0, m.translation, m.rotation, static=True)
    look = buffer.lookup(structure_frame, sensor.frame, times)
    acc = None if acceleration is None else look.rotate(np.asarray(acceleration, dtype=float).reshape(-1, 3))
    gaps = buffer.gaps(structure_frame, sensor.frame, int(times[0]), int(times[-1])) if times.size else []
    return SensorTrack(sensor.id, times, look.translation, acc, look.valid, gaps,
                       buffer.period_s(structure_frame, sensor.frame))


@dataclass
class Setup:
    """One setup: where each roving sensor stood, its segments as sample slices [i0, i1), its samples."""

    id: int
    points: dict[str, str]
    segments: list[tuple[int, int]]
    start_ns: int
    end_ns: int

    @property
    def samples(self) -> int:
        return int(sum(b - a for a, b in self.segments))

    def to_dict(self, references: Sequence[str]) -> dict:
        return {"id": self.id, "start": ns_to_iso(self.start_ns), "end": ns_to_iso(self.end_ns),
                "start_ns": self.start_ns, "end_ns": self.end_ns, "points": dict(self.points),
                "references": list(references), "samples": self.samples,
                "segments": [list(s) for s in self.segments]}


@dataclass
class SetupCut:
    """The setups, the samples left out (moving or off every point; no transform), and the gaps."""

    setups: list[Setup]
    moving_samples: int
    missing_samples: int
    short_samples: int  # at a point, but for less than the minimum dwell
    gaps: list[Gap] = field(default_factory=list)
    point_index: np.ndarray | None = None  # (n, sensors): point of each sample, -1 none, -2 missing
    # (n,): a roving sensor's filtered position beyond the tolerance of every point (before the
    # setups' edge guard): the drive phases as the filtered positions show them
    moving: np.ndarray | None = None

    def errors(self) -> list[str]:
        return [g.describe() for g in self.gaps]


def _filtered(position: np.ndarray, valid: np.ndarray, times_ns: np.ndarray, filter_s: float) -> np.ndarray:
    """Running median of each coordinate over ``filter_s``, within each stretch of valid samples."""
    out = np.full(position.shape, np.nan)
    if position.shape[0] < 2 or filter_s <= 0:
        out[valid] = position[valid]
        return out
    dt = float(np.median(np.diff(times_ns))) * 1e-9
    size = max(1, int(round(filter_s / dt)) | 1)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], valid.astype(int), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        # mirrored ends: "nearest" would repeat the edge sample half a window long and make its noise
        # the median (a last sample 6 cm off read as the robot leaving)
        out[a:b] = ndi.median_filter(position[a:b], size=(size, 1), mode="mirror")
    return out


def cut_setups(tracks: Sequence[SensorTrack], points: Sequence[MeasurementPoint],
               tolerance_m: float = DEFAULT_TOLERANCE_M, min_dwell_s: float = DEFAULT_MIN_DWELL_S,
               filter_s: float = DEFAULT_FILTER_S, max_split_s: float | None = None) -> SetupCut:
    """Setups from the tracks of every roving sensor (same sample times; see module doc). Two
    stretches at the same points separated only by missing transforms (at most ``max_split_s``, default
    no limit) are one setup."""
    if not tracks:
        raise ValueError("cut_setups needs the track of at least one roving sensor")
    times = tracks[0].times_ns
    if any(p.position is None for p in points):
        raise ValueError("every measurement point needs a position in the structure's frame (xyz)")
    pts = np.array([p.position for p in points], dtype=float)
    axes = np.array([p.axes for p in points], dtype=float)
    idx = np.empty((times.size, len(tracks)), dtype=int)
    for j, tr in enumerate(tracks):
        pos = _filtered(tr.position, tr.valid, times, filter_s)
        d = np.sqrt(np.sum(((pos[:, None, :] - pts[None, :, :]) * axes[None]) ** 2, axis=2))
        near = np.argmin(np.where(np.isfinite(d), d, np.inf), axis=1)
        ok = np.take_along_axis(d, near[:, None], axis=1)[:, 0] <= tolerance_m
        idx[:, j] = np.where(~tr.valid, -2, np.where(ok, near, -1))
    missing = np.any(idx == -2, axis=1)
    at_point = np.all(idx >= 0, axis=1)
    moving = np.any(idx == -1, axis=1) & ~missing
    key = [tuple(r) for r in idx]
    dt = float(np.median(np.diff(times))) * 1e-9 if times.size > 1 else 1.0
    min_n = int(np.ceil(min_dwell_s / dt))
    runs: list[tuple[int, int]] = []
    k = 0
    while k < times.size:
        if not at_point[k]:
            k += 1
            continue
        e = k
        while e < times.size and at_point[e] and key[e] == key[k]:
            e += 1
        runs.append((k, e))
        k = e
    setups: list[Setup] = []
    short = 0
    for a, b in runs:
        prev = setups[-1] if setups else None
        if prev is not None and key[a] == key[prev.segments[-1][0]] and missing[prev.segments[-1][1]:a].all() \
                and (max_split_s is None or (times[a] - times[prev.segments[-1][1] - 1]) * 1e-9 <= max_split_s):
            prev.segments.append((a, b))
            prev.end_ns = int(times[b - 1])
            continue
        setups.append(Setup(len(setups) + 1, {tr.sensor: points[key[a][j]].id for j, tr in enumerate(tracks)},
                            [(a, b)], int(times[a]), int(times[b - 1])))
    kept: list[Setup] = []
    guard = int(np.ceil(max(tr.tf_period_s for tr in tracks) / dt - 1e-9))
    for s in setups:
        if s.samples >= min_n:
            s.id = len(kept) + 1
            kept.append(s)
            _guard_edges(s, idx, guard, times)
        else:
            short += s.samples
    at_point = np.all(idx >= 0, axis=1)
    gaps = sorted({g for tr in tracks for g in tr.gaps}, key=lambda g: g.start_ns)
    return SetupCut(kept, int(np.sum(~at_point & ~missing)), int(np.sum(missing)), short, gaps, idx, moving)


def _guard_edges(setup: Setup, idx: np.ndarray, guard: int, times: np.ndarray) -> None:
    """Leave out ``guard`` samples (one tf period) at each end of the setup's segments where the robot
    arrived or left (not at the recording's ends, nor next to a missing transform): the filtered
    position says when it arrived or left only to within a tf period, and the samples of that
    period may hold its ride vibration, far stronger than the structure's response."""
    if guard <= 0:
        return
    segs = []
    n = idx.shape[0]
    for a, b in setup.segments:
        head = guard if a > 0 and not np.any(idx[a - 1] == -2) else 0
        tail = guard if b < n and not np.any(idx[b] == -2) else 0
        if b - a > head + tail:
            idx[a:a + head] = -1
            idx[b - tail:b] = -1
            segs.append((a + head, b - tail))
    if segs:
        setup.segments = segs
        setup.start_ns, setup.end_ns = int(times[segs[0][0]]), int(times[segs[-1][1] - 1])


def setup_channels(setup: Setup, references: Mapping[str, np.ndarray], roving: Mapping[str, np.ndarray]
                   ) -> tuple[np.ndarray, list[str]]:
    """The samples of one setup (its segments one after the other): the references' columns under
    their ids, each roving sensor's under the id of the point where it stood."""
    cols, names = [], []
    for rid, x in references.items():
        cols.append(np.concatenate([x[a:b] for a, b in setup.segments]))
        names.append(rid)
    for sid, x in roving.items():
        cols.append(np.concatenate([x[a:b] for a, b in setup.segments]))
        names.append(setup.points[sid])
    return np.column_stack(cols), names
