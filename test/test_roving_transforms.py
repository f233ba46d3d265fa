"""The transform buffer (shm_ros/core/roving/transforms.py) against chains computed by hand."""

from __future__ import annotations

import numpy as np
import pytest

from shm_ros.core.roving.transforms import Gap, TransformBuffer, TransformError

S = 1_000_000_000
C45 = np.sqrt(0.5)
YAW90 = [0.0, 0.0, C45, C45]
PITCH90 = [0.0, C45, 0.0, C45]
IDENT = [0.0, 0.0, 0.0, 1.0]


def _rep105(buf: TransformBuffer, until_s: float = 2.0, hz: float = 10.0) -> None:
    """map -> odom (dynamic, yaw 90), odom -> base_link (dynamic), base_link -> accel (static, pitch 90)."""
    for t in np.arange(0.0, until_s + 1e-9, 1.0 / hz):
        ns = int(round(t * S))
        buf.set_transform("map", "odom", ns, [1.0, 0.0, 0.0], YAW90)
        buf.set_transform("odom", "base_link", ns, [2.0, 0.0, 0.0], IDENT)
    buf.set_transform("base_link", "accel", 0, [0.0, 0.0, 0.5], PITCH90, static=True)


def test_three_link_chain_by_hand():
    buf = TransformBuffer()
    _rep105(buf)
    look = buf.lookup("map", "accel", [int(0.55 * S), int(1.5 * S)])
    assert look.valid.all()
    # accel origin: (0,0,0.5) in base -> (2,0,0.5) in odom -> Rz90 (2,0,0.5) + (1,0,0) = (1,2,0.5) in map
    np.testing.assert_allclose(look.translation, [[1.0, 2.0, 0.5]] * 2, atol=1e-12)
    # the accel's x axis: Ry90 x = -z, Rz90 (-z) = -z; its z axis: Ry90 z = x, Rz90 x = y
    axes = look.rotate(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    np.testing.assert_allclose(axes, [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0]], atol=1e-12)
    # the other way round is the inverse: the map origin seen from the accel
    back = buf.lookup("accel", "map", [int(0.55 * S)])
    # p_accel = R^T (p_map - t): R^T (-1,-2,-0.5) with R = Rz90 Ry90
    r = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]) @ \
        np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    np.testing.assert_allclose(back.translation[0], r.T @ [-1.0, -2.0, -0.5], atol=1e-12)
    # siblings: from odom to accel goes up to odom only
    sib = buf.lookup("odom", "accel", [S])
    np.testing.assert_allclose(sib.translation[0], [2.0, 0.0, 0.5], atol=1e-12)


def test_time_interpolation_linear_and_slerp():
    buf = TransformBuffer()
    buf.set_transform("odom", "base", 0, [0.0, 0.0, 0.0], IDENT)
    buf.set_transform("odom", "base", S, [2.0, -4.0, 1.0], YAW90)
    look = buf.lookup("odom", "base", [S // 4, S // 2])
    np.testing.assert_allclose(look.translation, [[0.5, -1.0, 0.25], [1.0, -2.0, 0.5]], atol=1e-12)
    for k, yaw in enumerate((np.pi / 8, np.pi / 4)):  # slerp about a fixed axis: the angle is linear
        np.testing.assert_allclose(look.rotation[k], [0, 0, np.sin(yaw / 2), np.cos(yaw / 2)], atol=1e-12)
    # q and -q are one rotation: slerp takes the short way
    buf.set_transform("odom", "base", 2 * S, [2.0, -4.0, 1.0], [-v for v in YAW90])
    mid = buf.lookup("odom", "base", [int(1.5 * S)])
    np.testing.assert_allclose(np.abs(mid.rotation[0]), np.abs(YAW90), atol=1e-12)


def test_out_of_order_stamps_and_bounded_history():
    buf = TransformBuffer(cache_s=10.0)
    stamps = np.arange(0, 301) * (S // 10)  # 30 s at 10 Hz
    rng = np.random.default_rng(0)
    for ns in rng.permutation(stamps[:50]):  # the first 5 s arrive shuffled
        buf.set_transform("a", "b", int(ns), [ns / S, 0, 0], IDENT)
    look = buf.lookup("a", "b", [int(2.35 * S)])
    np.testing.assert_allclose(look.translation[0], [2.35, 0, 0], atol=1e-12)
    for ns in stamps[50:]:
        buf.set_transform("a", "b", int(ns), [ns / S, 0, 0], IDENT)
    assert not buf.lookup("a", "b", [int(19.0 * S)]).valid[0]  # older than 10 s behind the newest
    assert buf.lookup("a", "b", [int(20.05 * S)]).valid[0]
    assert len(buf._edges["b"].stamps) == 101


def test_missing_transform_is_a_gap_naming_the_frames():
    buf = TransformBuffer(cache_s=None)
    for t in np.arange(0.0, 30.0, 0.1):
        if not 10.0 < t < 20.0:
            buf.set_transform("structure", "rover/base_link", int(round(t * S)), [t, 0, 0], IDENT)
    buf.set_transform("rover/base_link", "rover/accel", 0, [0, 0, 0.1], IDENT, static=True)
    times = np.array([5.0, 10.05, 15.0, 19.95, 25.0]) * S
    look = buf.lookup("structure", "rover/accel", times.astype(np.int64))
    assert look.valid.tolist() == [True, False, False, False, True]
    assert np.isnan(look.translation[1:4]).all()  # never a default position
    gaps = buf.gaps("structure", "rover/accel", 0, int(29.9 * S))
    assert gaps == [Gap("structure", "rover/base_link", 10 * S, 20 * S)]
    assert "structure -> rover/base_link" in gaps[0].describe()
    # before the first and after the last stamp: missing too
    assert [(g.start_ns, g.end_ns) for g in buf.gaps("structure", "rover/accel", -S, 31 * S)] == [
        (-S, 0), (10 * S, 20 * S), (int(round(29.9 * S)), 31 * S)]


def test_gap_limit_is_half_a_second_or_five_periods():
    fast = TransformBuffer()
    for t in [0.0, 0.1, 0.2, 0.6, 0.7, 1.4, 1.5]:  # 10 Hz: 0.4 s is no gap, 0.7 s is
        fast.set_transform("a", "b", int(round(t * S)), [0, 0, 0], IDENT)
    assert fast.lookup("a", "b", [int(0.4 * S), int(1.0 * S)]).valid.tolist() == [True, False]
    slow = TransformBuffer(cache_s=None)
    for t in [0, 1, 2, 3, 7, 8, 9, 15, 16]:  # 1 Hz: 4 s is no gap (< 5 periods), 6 s is
        slow.set_transform("a", "b", t * S, [0, 0, 0], IDENT)
    assert slow.lookup("a", "b", [5 * S, 12 * S]).valid.tolist() == [True, False]


def test_map_odom_jump_is_followed():
    buf = TransformBuffer(cache_s=None)
    for k in range(30):
        ns = k * S // 10
        buf.set_transform("map", "odom", ns, [0.0 if k < 15 else 0.3, 0, 0], IDENT)
        buf.set_transform("odom", "base", ns, [0.01 * k, 0, 0], IDENT)
    x = buf.lookup("map", "base", np.array([1.0, 1.45, 2.0]) * S).translation[:, 0]
    np.testing.assert_allclose(x, [0.10, 0.145 + 0.15, 0.20 + 0.3], atol=1e-12)


def test_unconnected_frames_and_bad_input():
    buf = TransformBuffer()
    buf.set_transform("structure", "rover/base_link", 0, [0, 0, 0], IDENT)
    with pytest.raises(TransformError, match="'structure' to 'rover/accel_link'"):
        buf.lookup("structure", "rover/accel_link", [0])
    with pytest.raises(ValueError, match="unit quaternion"):
        buf.set_transform("a", "b", 0, [0, 0, 0], [0, 0, 0, 2])
