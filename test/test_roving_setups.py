"""Where a roving sensor is (tf chain + mount) and the setups cut where it dwells
(shm_ros/core/roving/setups.py), on a robot driving between four points of the girder with
localisation noise (2 cm), REP-105 map -> odom corrections, a 10 s pose gap and a tilted mount."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from shm_ros.core.roving.setups import cut_setups, sensor_track
from shm_ros.core.roving.transforms import TransformBuffer, TransformError
from shm_ros.io.structure import load_structure

S = 1_000_000_000
FS = 100.0
TF_HZ = 10.0
G = 9.81
SPEC = load_structure(Path(__file__).resolve().parents[1] / "examples" / "girder_roving.yaml")
POINTS = SPEC.measurement_points[:4]
DWELL_S, SPEED = 30.0, 1.0
GAP = (75.0, 85.0)  # no odom -> base_link in this stretch (inside the third dwell)


def _plan():
    """Phases (kind, t0, t1, x0, x1) of the sensor's x: dwell, drive, dwell, ..."""
    phases, t = [], 0.0
    xs = [p.position[0] for p in POINTS]
    for k, x in enumerate(xs):
        phases.append(("dwell", t, t + DWELL_S, x, x))
        t += DWELL_S
        if k + 1 < len(xs):
            dur = abs(xs[k + 1] - x) / SPEED
            phases.append(("drive", t, t + dur, x, xs[k + 1]))
            t += dur
    return phases


def _sensor_x(t: np.ndarray, phases) -> np.ndarray:
    x = np.empty_like(t)
    for _, t0, t1, x0, x1 in phases:
        m = (t >= t0) & (t <= t1)
        x[m] = x0 + (x1 - x0) * (t[m] - t0) / max(t1 - t0, 1e-12)
    return x


def _buffer(seed: int, phases, gap=GAP) -> TransformBuffer:
    """structure (= map) -> odom -> rover/base_link: odometry drifts 1 % of the distance driven, the
    localiser removes the drift once a second (a map -> odom jump); 2 cm noise on the pose."""
    rng = np.random.default_rng(seed)
    buf = TransformBuffer(cache_s=None)
    mount = np.array(SPEC.roving[0].mount.translation)
    end = phases[-1][2]
    drift = 0.0
    last_x = _sensor_x(np.array([0.0]), phases)[0]
    correction = 0.0
    ident = [0.0, 0.0, 0.0, 1.0]
    for t in np.arange(0.0, end + 1e-9, 1.0 / TF_HZ):
        x = _sensor_x(np.array([t]), phases)[0]
        drift += 0.01 * abs(x - last_x)
        last_x = x
        if abs(t - round(t)) < 1e-9:
            correction = -drift
        ns = int(round(t * S))
        buf.set_transform("structure", "odom", ns, [correction, 0.0, 0.0], ident)
        if gap is None or not gap[0] < t < gap[1]:
            base = np.array([x - mount[0] + drift, 0.0, 0.3]) + rng.normal(0.0, 0.02, 3)
            buf.set_transform("odom", "rover/base_link", ns, base, ident)
    return buf


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_setups_cut_where_the_sensor_dwells(seed):
    phases = _plan()
    buf = _buffer(seed, phases)
    times = np.arange(0.0, phases[-1][2], 1.0 / FS)
    tns = np.round(times * S).astype(np.int64)
    track = sensor_track(buf, SPEC.frame, SPEC.roving[0], tns)
    cut = cut_setups([track], SPEC.measurement_points, min_dwell_s=20.0)
    assert [s.points for s in cut.setups] == [{"r1": p.id} for p in POINTS]
    # the pose gap: an error naming the frames and the stretch; the rest of that setup used
    (gap,) = cut.gaps
    assert (gap.parent, gap.child) == ("odom", "rover/base_link")
    assert abs(gap.start_ns / S - GAP[0]) <= 0.1 and abs(gap.end_ns / S - GAP[1]) <= 0.1
    assert "odom -> rover/base_link" in cut.errors()[0]
    third = cut.setups[2]
    assert len(third.segments) == 2 and not np.any(np.isnan(track.position[third.segments[0][0]:third.segments[0][1]]))
    # every setup keeps >= 95 % of its dwell's samples (the gap's samples are not the setup's)
    dwell = [p for p in phases if p[0] == "dwell"]
    for s, (_, t0, t1, _, _) in zip(cut.setups, dwell, strict=True):
        n = np.sum((times >= t0) & (times <= t1) & ~((times > GAP[0]) & (times < GAP[1])))
        assert s.samples >= 0.95 * n, (s.id, s.samples, n)
        inside = np.concatenate([np.arange(a, b) for a, b in s.segments])
        assert np.all((times[inside] >= t0 - 0.1) & (times[inside] <= t1 + 0.1))
    # the samples left out lie within one tf period of a drive phase (or in the gap)
    left = np.flatnonzero(np.all(cut.point_index == -1, axis=1))
    near_drive = np.zeros(times.size, bool)
    for kind, t0, t1, _, _ in phases:
        if kind == "drive":
            near_drive |= (times >= t0 - 1 / TF_HZ) & (times <= t1 + 1 / TF_HZ)
    assert near_drive[left].all(), times[left[~near_drive[left]]][:10]
    assert cut.moving_samples == left.size and cut.missing_samples > 0.95 * (GAP[1] - GAP[0]) * FS


def test_tilted_mount_rotates_the_acceleration_into_the_structure():
    phases = _plan()
    buf = _buffer(0, phases, gap=None)
    times = np.round(np.arange(0.0, 20.0, 1.0 / FS) * S).astype(np.int64)
    rng = np.random.default_rng(4)
    a_z = 0.05 * rng.standard_normal(times.size)  # the deck's vertical acceleration
    pitch = np.radians(20.0)  # the mount's pitch (examples/girder_roving.yaml)
    # what the tilted sensor reads in its own axes: R^T (0, 0, g + a_z), R = rotation about y
    raw = np.column_stack([-np.sin(pitch) * (G + a_z), np.zeros_like(a_z), np.cos(pitch) * (G + a_z)])
    track = sensor_track(buf, SPEC.frame, SPEC.roving[0], times, raw)
    np.testing.assert_allclose(track.acceleration[:, 2], G + a_z, atol=1e-9)
    np.testing.assert_allclose(track.acceleration[:, :2], 0.0, atol=1e-9)
    # the mount's offset: the sensor is 0.2 m ahead of and 0.15 m above the base (+ 2 cm noise)
    assert np.all(np.abs(track.position[:, 2] - 0.45) < 0.1)


def test_missing_mount_is_a_clear_error():
    phases = _plan()
    buf = _buffer(0, phases, gap=None)
    sensor = dataclasses.replace(SPEC.roving[0], mount=None)
    with pytest.raises(TransformError, match=r"roving sensor 'r1'.*'rover/accel_link'.*no /tf_static"):
        sensor_track(buf, SPEC.frame, sensor, np.array([S]))
