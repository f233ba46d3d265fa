"""Bags (MCAP, zstd MCAP, sqlite3) -> windows: exact samples, ignored topics, faults, damage."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from shm_ros.core.types import SampleFlag
from shm_ros.core.ingest import ChannelMap, ChannelSource
from shm_ros.io.bags import IMU, BagWriter, read_messages
from shm_ros.io.imu_cdr import decode_imu_batch
from shm_ros.io.recording import ingest_bag, windows_from_bag
from shm_ros.io.typestore import typestore

T0 = 1_714_521_600_000_000_000
FS = 200.0
P = 5_000_000
FULL = os.environ.get("SHM_FULL") == "1"


def _cmap() -> ChannelMap:
    return ChannelMap([
        ChannelSource("s1", "s1", "z", None, 1.0),
        ChannelSource("s2", "s2", "z", None, 1.0),
        ChannelSource("h2", "s2", "x", None, -1.0),  # second axis of the same IMU, sign -1
        ChannelSource("b1", None, "z", "b1", 1.0),
        ChannelSource("b2", None, "z", "b2", 1.0),
    ], input_sensor="b1")


def _write(path: Path, storage: str, compress: bool, seconds: float, rng, faults=None):
    """Two IMUs (jittered stamps, receive times after them) + a DAQ block stream + noise topics."""
    n = int(seconds * FS)
    grid = T0 + np.arange(n, dtype=np.int64) * P
    imu = {s: rng.standard_normal((n, 3)) * 0.02 + np.array([0.1, -0.2, 9.81]) for s in ("s1", "s2")}
    stamps = {s: grid + rng.integers(-int(0.3 * P), int(0.3 * P), n) for s in ("s1", "s2")}
    stamps["s1"][0] = grid[0]
    stamps["s2"][0] = grid[0] + 1
    block = rng.standard_normal((n, 2)) * 0.01
    if faults:
        faults(imu, stamps, block)
    step = int(0.5 * FS)
    with BagWriter(path, storage=storage, compress=compress, frame_id="imu_link") as w:
        types = w._types
        for i in range(0, n, step):
            sl = slice(i, min(n, i + step))
            for s in ("s1", "s2"):
                w.imu_series(f"/bridge/accel/{s}", stamps[s][sl], imu[s][sl],
                             receive_ns=grid[sl] + 3_000_000)  # arrival: monotonic, after the stamp
            w.accel_block("/bridge/daq/accel_block", int(grid[i]), FS, ["b1", "b2", "unused"],
                          np.column_stack((block[sl], np.zeros(sl.stop - sl.start))))
            # unrelated topics, including an Imu that is not an accel topic
            w.write("/tf_static", "std_msgs/msg/String", int(grid[i]), types["std_msgs/msg/String"](data="x"))
            w.imu_series("/imu/data", grid[sl][:2], np.ones((2, 3)))
            if i % int(5 * FS) == 0:
                w.temperature("/bridge/temperature/deck", int(grid[i]), 10.0 + i / n)
    return grid, imu, stamps, block


@pytest.mark.parametrize("storage,compress", [("mcap", False), ("mcap", True), ("sqlite3", False)])
def test_bag_windows_hold_exactly_the_samples(tmp_path, storage, compress):
    rng = np.random.default_rng(1)
    seconds = 64.0 if FULL else 24.0  # a 4 s remainder (< half a window) is dropped
    grid, imu, stamps, block = _write(tmp_path / "bag", storage, compress, seconds, rng)
    res = ingest_bag(tmp_path / "bag", _cmap(), window_s=10.0)
    ws = res.windows
    n_win = int(seconds // 10)
    assert len(ws) == n_win
    assert all(w.n_samples == 2000 for w in ws)
    got = np.concatenate([w.samples for w in ws])
    m = got.shape[0]
    # bit-identical raw values, in order; sign -1 is an exact negation
    assert np.array_equal(got[:, 0], imu["s1"][:m, 2])
    assert np.array_equal(got[:, 1], imu["s2"][:m, 2])
    assert np.array_equal(got[:, 2], -imu["s2"][:m, 0])
    assert np.array_equal(got[:, 3:], block[:m])
    assert [w.start_ns for w in ws] == [int(grid[0]) + k * 2000 * P for k in range(n_win)]
    assert all(w.flags is None and w.channel_status == ["ok"] * 5 for w in ws)
    assert ws[0].input_channel == "b1"
    assert ws[0].temperature_c == pytest.approx(10.0 + 0.5 * 1000 / len(grid))  # at 0 s and 5 s
    # unrelated topics ignored and listed
    assert "/tf_static (std_msgs/msg/String)" in res.ignored_topics
    assert any(t.startswith("/imu/data") for t in res.ignored_topics)
    assert res.stats.samples_windowed == m * 5
    assert not [d for d in res.diagnostics if d.level >= 2]


def test_imu_batch_decoding_matches_rosbags(tmp_path):
    rng = np.random.default_rng(2)
    ts = typestore()
    datas, ref = [], []
    for frame in ("", "a", "imu_link", "sensor_frame_long_name_12"):
        with BagWriter(tmp_path / f"b{len(frame)}", frame_id=frame) as w:
            st = T0 + np.arange(20, dtype=np.int64) * P + rng.integers(0, 999_999_999, 20)
            w.imu_series("/a/accel/x", st, rng.standard_normal((20, 3)))
        for m in read_messages(tmp_path / f"b{len(frame)}"):
            datas.append(m.data)
            msg = ts.deserialize_cdr(m.data, IMU)
            la = msg.linear_acceleration
            ref.append((msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec, la.x, la.y, la.z))
    stamps, xyz = decode_imu_batch(datas)
    ref = np.asarray(ref, dtype=object)
    assert np.array_equal(stamps, ref[:, 0].astype(np.int64))
    assert np.array_equal(xyz, ref[:, 1:].astype(np.float64))


def _faults(imu, stamps, block):
    n = stamps["s1"].size
    imu["s1"][1000, 2] = np.nan  # NaN
    stamps["s2"][3000:3040] = stamps["s2"][3000:3040] + 200 * P  # 40 stamps jump ahead: a gap
    stamps["s1"][2500] = stamps["s1"][2499]  # duplicated stamp
    stamps["s1"][4300:4350] -= int(30e9)  # clock jump backwards by 30 s
    block[:, 1] = 0.25  # dead channel b2
    x = np.sin(2 * np.pi * 0.7 * np.arange(n) / FS) * 4.0
    imu["s2"][:, 2] = np.clip(x, -3.0, 3.0) + 9.81  # clipped (flat tops at 6.81 / 12.81)


def test_injected_faults_give_clear_diagnostics(tmp_path):
    rng = np.random.default_rng(3)
    _write(tmp_path / "bag", "mcap", False, 30.0, rng, faults=_faults)
    # an accel topic that is not in the structure
    with BagWriter(tmp_path / "bag2") as w:
        w.imu_series("/bridge/accel/zz", T0 + np.arange(10, dtype=np.int64) * P, np.zeros((10, 3)))
    ws, diags = windows_from_bag(tmp_path / "bag", _cmap(), window_s=10.0)
    by_code: dict[str, list] = {}
    for d in diags:
        by_code.setdefault(d.code, []).append(d)
    assert any("accel/s1" in d.source for d in by_code["nan"])
    assert any("accel/s1" in d.source for d in by_code["duplicate_stamp"])
    assert any("accel/s2" in d.source for d in by_code["gap"])
    assert any("accel/s1" in d.source for d in by_code["late_sample"] + by_code.get("out_of_order", []))
    assert any("b2" in d.source for d in by_code["dead_channel"])
    assert any("accel/s2" in d.source for d in by_code["clipped"])
    # flagged, not dropped: the NaN sample is in its window at its time, flagged
    w0 = ws[0]
    assert np.isnan(w0.samples[1000, 0]) and w0.flags[1000, 0] & SampleFlag.NAN
    assert w0.channel_status[4] == "dead" and w0.channel_status[1] == "clipped"
    _, diags2 = windows_from_bag(tmp_path / "bag2", _cmap(), window_s=10.0)
    assert any(d.code == "unknown_topic" and "accel/zz" in d.source for d in diags2)


def _truncate(bag: Path, fraction: float) -> Path:
    f = next(p for p in bag.iterdir() if p.suffix in (".mcap", ".db3"))
    size = f.stat().st_size
    with open(f, "r+b") as fh:
        fh.truncate(int(size * fraction))
    return f


def test_truncated_mcap_keeps_windows_before_the_damage(tmp_path):
    rng = np.random.default_rng(4)
    seconds = 40.0
    _write(tmp_path / "full", "mcap", True, seconds, np.random.default_rng(4))
    full = ingest_bag(tmp_path / "full", _cmap(), window_s=5.0).windows
    _write(tmp_path / "cut", "mcap", True, seconds, rng)
    f = _truncate(tmp_path / "cut", 0.6)
    res = ingest_bag(tmp_path / "cut", _cmap(), window_s=5.0)
    assert 2 <= len(res.windows) < len(full)
    for a, b in zip(res.windows, full, strict=False):
        assert a.start_ns == b.start_ns and np.array_equal(a.samples, b.samples)
    errs = [d for d in res.diagnostics if d.code == "bag_damaged"]
    assert errs and str(f) in errs[0].message


def test_damaged_sqlite_bag_reports_and_does_not_raise(tmp_path):
    _write(tmp_path / "bag", "sqlite3", False, 10.0, np.random.default_rng(5))
    _truncate(tmp_path / "bag", 0.5)
    ws, diags = windows_from_bag(tmp_path / "bag", _cmap(), window_s=5.0)
    errs = [d for d in diags if d.code == "bag_damaged" and d.level == 2]
    assert errs and str(tmp_path / "bag") in errs[0].source
    ws2, diags2 = windows_from_bag(tmp_path / "missing", _cmap(), window_s=5.0)
    assert ws2 == [] and any("no such bag" in d.message for d in diags2)


@pytest.mark.parametrize("compress", [False, True])
def test_sqlite_bag_without_metadata_is_read_row_by_row(tmp_path, compress):
    """A recorder killed before writing metadata.yaml leaves a complete .db3: every window is
    recovered exactly (per-message zstd included), with a warning naming the bag; replay reads
    it the same way."""
    from shm_ros.ros.replay import _open_bag

    _write(tmp_path / "bag", "sqlite3", compress, 12.0, np.random.default_rng(6))
    full = ingest_bag(tmp_path / "bag", _cmap(), window_s=5.0).windows
    reference = [(m.topic, m.receive_ns, m.data) for m in read_messages(tmp_path / "bag")]
    (tmp_path / "bag" / "metadata.yaml").unlink()
    res = ingest_bag(tmp_path / "bag", _cmap(), window_s=5.0)
    assert len(res.windows) == len(full) >= 2
    for a, b in zip(res.windows, full, strict=False):
        assert a.start_ns == b.start_ns and np.array_equal(a.samples, b.samples)
    warn = [d for d in res.diagnostics if d.code == "bag_damaged"]
    assert warn and warn[0].level == 1 and "metadata" in warn[0].message
    found, reader, note = _open_bag(tmp_path / "bag")
    assert "metadata" in note
    assert "/bridge/accel/s1" in found and found["/bridge/accel/s1"] == IMU
    got = [(m.topic, m.receive_ns, m.data) for m in reader(list(found))]
    assert sorted(got) == sorted(reference)


def test_garbled_sqlite_bag_keeps_the_rows_before_the_damage(tmp_path):
    _write(tmp_path / "full", "sqlite3", False, 40.0, np.random.default_rng(7))
    full = ingest_bag(tmp_path / "full", _cmap(), window_s=5.0).windows
    _write(tmp_path / "bad", "sqlite3", False, 40.0, np.random.default_rng(7))
    (tmp_path / "bad" / "metadata.yaml").unlink()
    f = next((tmp_path / "bad").glob("*.db3"))
    with open(f, "r+b") as fh:  # overwrite a stretch in the middle of the file
        fh.seek(f.stat().st_size // 2)
        fh.write(np.random.default_rng(0).bytes(20000))
    res = ingest_bag(tmp_path / "bad", _cmap(), window_s=5.0)
    assert 1 <= len(res.windows) < len(full)
    for a, b in zip(res.windows[:-1], full, strict=False):  # the last one may end at the damage
        assert a.start_ns == b.start_ns and np.array_equal(a.samples, b.samples)
    errs = [d for d in res.diagnostics if d.code == "bag_damaged" and d.level == 2]
    assert errs and str(f) in errs[0].message and "damaged sqlite3" in errs[0].message
