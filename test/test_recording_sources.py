"""Bag back ends (shm_ros.io.sources): every back end gives the same messages for the same bag,
damaged files give a prefix and an error naming the file, a bug in a back end is raised (never
re-read another way), and no message is fed to the ingest core twice."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from test_recording_bags import _cmap, _truncate, _write

from shm_ros.core.ingest import IngestCore
from shm_ros.io import recording
from shm_ros.io.bags import IMU, BagError, BagWriter, read_messages
from shm_ros.io.imu_cdr import decode_imu_batch, decode_imu_views
from shm_ros.io.sources import mcap_chunks, open_source
from shm_ros.io.sources.mcap_chunks import McapChunkSource
from shm_ros.io.sources.rosbags_reader import RosbagsSource
from shm_ros.io.sources.salvage import McapRecordSource
from shm_ros.io.sources.sqlite_rows import MessageCompression, RowOrder, SqliteSource
from shm_ros.io.typestore import typestore

SECONDS = 8.0


def _by_topic(messages) -> dict[str, list[tuple[int, bytes]]]:
    out: dict[str, list[tuple[int, bytes]]] = {}
    for m in messages:
        out.setdefault(m.topic, []).append((m.receive_ns, m.data))
    return out


def _bag(tmp_path: Path, storage: str, compress: bool, metadata: bool = True, seconds: float = SECONDS):
    written = _write(tmp_path / "bag", storage, compress, seconds, np.random.default_rng(11))
    reference = list(read_messages(tmp_path / "bag"))  # rosbags, with the metadata
    if not metadata:
        (tmp_path / "bag" / "metadata.yaml").unlink()
    return written, reference


CASES = [  # storage, compressed, metadata.yaml kept, back end, what it says about the bag
    ("mcap", False, True, McapChunkSource, ""),
    ("mcap", True, True, McapChunkSource, ""),  # zstd chunks
    ("sqlite3", False, True, SqliteSource, ""),
    ("sqlite3", True, True, SqliteSource, ""),  # zstd per message
    ("sqlite3", False, False, SqliteSource, "metadata"),
    ("sqlite3", True, False, SqliteSource, "metadata"),
    ("mcap", False, False, McapChunkSource, "metadata"),
]


@pytest.mark.parametrize("storage,compress,metadata,backend,note", CASES)
def test_every_source_gives_the_same_messages(tmp_path, storage, compress, metadata, backend, note):
    (grid, imu, stamps, _), reference = _bag(tmp_path, storage, compress, metadata)
    source = open_source(tmp_path / "bag")
    assert type(source) is backend
    assert (note in source.note) if note else source.note == ""
    if isinstance(source, SqliteSource):
        assert source.order is (RowOrder.RECEIVED if metadata else RowOrder.WRITTEN)
        assert source.compression is (MessageCompression.DETECT if not metadata else
                                      MessageCompression.ZSTD if compress else MessageCompression.NONE)
    assert source.topics() == {m.topic: m.msgtype for m in reference}
    got = list(source.messages())
    # the same messages, each once: per topic the same receive times and bytes in the same order
    assert len(got) == len(reference)
    assert Counter((m.topic, m.receive_ns, m.data) for m in got) == \
        Counter((m.topic, m.receive_ns, m.data) for m in reference)
    assert _by_topic(got) == _by_topic(reference)
    assert all(a.receive_ns <= b.receive_ns for a, b in zip(got, got[1:], strict=False))
    # ... and the values written: stamps and accelerations of an Imu topic
    t, xyz = decode_imu_batch([d for _, d in _by_topic(got)["/bridge/accel/s2"]])
    assert np.array_equal(t, stamps["s2"]) and np.array_equal(xyz, imu["s2"])
    # batches hold the same messages as messages(), each receive-ordered per topic
    runs = [r for b in source.batches() for r in b.runs]
    assert sum(len(r) for r in runs) == len(got)
    assert all(np.all(np.diff(r.log_ns) >= 0) for r in runs)
    # a topic filter
    only = list(source.messages(["/bridge/temperature/deck"]))
    assert _by_topic(only) == {"/bridge/temperature/deck": _by_topic(reference)["/bridge/temperature/deck"]}


def test_per_message_compressed_mcap_goes_to_rosbags(tmp_path):
    from rosbags.rosbag2 import CompressionFormat, CompressionMode

    path = tmp_path / "msgz"
    w = BagWriter(path)
    w._writer.set_compression(CompressionMode.MESSAGE, CompressionFormat.ZSTD)
    with w:
        w.imu_series("/a/accel/x", 1_000 + np.arange(20, dtype=np.int64), np.ones((20, 3)))
    source = open_source(path)
    assert isinstance(source, RosbagsSource)
    assert [m.receive_ns for m in source.messages()] == (1_000 + np.arange(20)).tolist()


def test_truncated_mcap_is_salvaged_up_to_the_damage(tmp_path):
    _, reference = _bag(tmp_path, "mcap", True, seconds=40.0)  # several chunks
    f = _truncate(tmp_path / "bag", 0.6)
    source = open_source(tmp_path / "bag")
    assert isinstance(source, McapRecordSource)
    assert str(f) in source.note and "truncated" in source.note
    got = []
    with pytest.raises(BagError, match="truncated") as err:
        for m in source.messages():
            got.append(m)
    assert str(f) in str(err.value)
    assert 0 < len(got) < len(reference)
    full = _by_topic(reference)
    for topic, msgs in _by_topic(got).items():  # a prefix of every topic
        assert msgs == full[topic][:len(msgs)]
    # ingest: the same prefix, each message fed once, and a diagnostic naming the file
    res = recording.ingest_bag(tmp_path / "bag", _cmap(), window_s=2.0)
    assert res.messages == len(got)
    damaged = [d for d in res.diagnostics if d.code == "bag_damaged" and d.level == 2]
    assert len(damaged) == 1 and str(f) in damaged[0].message


def test_truncated_sqlite_is_read_row_by_row_and_reported(tmp_path):
    _bag(tmp_path, "sqlite3", False, seconds=40.0)
    f = _truncate(tmp_path / "bag", 0.5)
    source = open_source(tmp_path / "bag")
    assert isinstance(source, SqliteSource) and source.order is RowOrder.WRITTEN
    assert str(f) in source.note and "cut short" in source.note
    with pytest.raises(BagError) as err:
        list(source.messages())
    assert str(f) in str(err.value)


def _count_fed(monkeypatch) -> Counter:
    fed: Counter = Counter()
    add = IngestCore.add_accel

    def counting(self, topic_id, stamps_ns, xyz, **kw):
        fed.update((topic_id, int(t)) for t in np.asarray(stamps_ns).tolist())
        return add(self, topic_id, stamps_ns, xyz, **kw)

    monkeypatch.setattr(IngestCore, "add_accel", counting)
    return fed


@pytest.mark.parametrize("storage,compress,truncate", [("mcap", False, False), ("mcap", True, True),
                                                       ("sqlite3", False, False)])
def test_no_message_is_fed_twice(tmp_path, monkeypatch, storage, compress, truncate):
    (_, _, stamps, _), _ = _bag(tmp_path, storage, compress, seconds=40.0)
    if truncate:
        _truncate(tmp_path / "bag", 0.5)
    fed = _count_fed(monkeypatch)
    recording.ingest_bag(tmp_path / "bag", _cmap(), window_s=2.0)
    assert fed and max(fed.values()) == 1  # stamps are unique per sensor in this bag
    n = stamps["s1"].size
    if truncate:
        assert 0 < sum(1 for s, _ in fed if s == "s1") < n
    else:
        assert sorted(t for s, t in fed if s == "s1") == sorted(stamps["s1"].tolist())


def test_a_bug_in_the_fast_path_is_raised_not_read_again(tmp_path, monkeypatch):
    _bag(tmp_path, "mcap", False, seconds=40.0)
    calls = []
    decode = mcap_chunks.decode_chunk

    def buggy(record, channels, where):
        calls.append(where)
        if len(calls) > 1:  # after the first chunk has been fed
            raise TypeError("a bug")
        return decode(record, channels, where)

    monkeypatch.setattr(mcap_chunks, "decode_chunk", buggy)
    fed = _count_fed(monkeypatch)
    with pytest.raises(TypeError, match="a bug"):
        recording.ingest_bag(tmp_path / "bag", _cmap(), window_s=2.0)
    assert len(calls) == 2 and fed  # stopped at the bug, nothing read again
    assert max(fed.values()) == 1

    def broken(record, channels, where):
        raise TypeError("a bug")

    monkeypatch.setattr(mcap_chunks, "decode_chunk", broken)
    with pytest.raises(TypeError, match="a bug"):
        recording.ingest_bag(tmp_path / "bag", _cmap(), window_s=2.0)


def _imu(ts, sec: int, frame: str, xyz) -> object:
    T = ts.types
    return T[IMU](
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=123), frame_id=frame),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=np.zeros(9),
        angular_velocity=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0), angular_velocity_covariance=np.zeros(9),
        linear_acceleration=T["geometry_msgs/msg/Vector3"](x=xyz[0], y=xyz[1], z=xyz[2]),
        linear_acceleration_covariance=np.zeros(9))


def test_imu_decoder_reads_both_byte_orders_and_reports_bad_messages():
    ts = typestore()
    rng = np.random.default_rng(3)
    datas, want_t, want_xyz = [], [], []
    for k, frame in enumerate(["", "a", "imu_link", "x" * 29]):
        for little in (True, False):
            xyz = rng.standard_normal(3)
            sec = -3 + k  # negative seconds are int32 on the wire
            datas.append(bytes(ts.serialize_cdr(_imu(ts, sec, frame, xyz), IMU, little_endian=little)))
            want_t.append(sec * 1_000_000_000 + 123)
            want_xyz.append(xyz)
    t, xyz = decode_imu_batch(datas)
    assert np.array_equal(t, want_t) and np.array_equal(xyz, np.asarray(want_xyz))
    # a malformed message among good ones: reported by index, the others kept
    bad = datas[:2] + [b"\x00\x01\x00\x00" + bytes(40)] + datas[2:]
    lengths = np.array([len(d) for d in bad])
    out = decode_imu_views(np.frombuffer(b"".join(bad), np.uint8),
                           np.concatenate(([0], np.cumsum(lengths)[:-1])), lengths)
    assert [i for i, _ in out.failures] == [2]
    assert np.array_equal(out.stamps_ns, want_t) and np.array_equal(out.xyz, np.asarray(want_xyz))
    with pytest.raises(ValueError, match="message 2"):
        decode_imu_batch(bad)


def test_a_damaged_chunk_in_a_complete_mcap_ends_the_read_with_an_error(tmp_path):
    _, reference = _bag(tmp_path, "mcap", False, seconds=40.0)
    source = open_source(tmp_path / "bag")
    assert isinstance(source, McapChunkSource)
    f = source.files[0]
    second = sorted(f.chunk_indexes, key=lambda ci: ci.chunk_start_offset)[1]
    assert second.compression == ""
    with open(f.path, "r+b") as fh:  # garble the first record header inside the second chunk
        fh.seek(second.chunk_start_offset + 9 + 8 + 8 + 8 + 4 + 4 + 8)
        fh.write(b"\xff" * 9)
    got = []
    with pytest.raises(BagError, match="chunk at byte") as err:
        for m in open_source(tmp_path / "bag").messages():
            got.append(m)
    assert str(f.path) in str(err.value)
    full = _by_topic(reference)
    assert got and all(msgs == full[t][:len(msgs)] for t, msgs in _by_topic(got).items())
