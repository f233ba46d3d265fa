"""A recorder's bag survives the recorder: a writer killed in the middle of a write (the fault hook
``SHM_FAULT=bag:write:K``, with a record large enough to be partly on disk) loses at most that
message; the next writer takes up the split cut short, writes a new split, and the bag opens as one
bag without salvage, every message once, in order. A full disk stops the writing with a clear
error and keeps what was written."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

MSGTYPE = "shm_interfaces/msg/ModalEstimate"
TOPIC = "/shm/modal_estimates"


def _cdr(window_id: str, frame_id: str = "frame", pad: int = 0) -> bytes:
    """A ModalEstimate message's CDR; ``pad`` sensor ids make it large."""
    from shm_ros.io.typestore import typestore

    ts = typestore()
    T = ts.types
    stamp = T["builtin_interfaces/msg/Time"](sec=1, nanosec=2)
    msg = T[MSGTYPE](header=T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id), window_id=window_id,
                     start=stamp, end=stamp, has_temperature=False, temperature_c=0.0, method="ssi-cov",
                     sensor_ids=["s" * 40] * pad, modes=[], covariate_names=[],
                     covariate_values=np.zeros(0))
    return bytes(ts.serialize_cdr(msg, MSGTYPE))


WRITER = """
import sys
from pathlib import Path
sys.path.insert(0, {test!r})
from test_bag_splits import _cdr, TOPIC, MSGTYPE
from shm_ros.io.bag_splits import SplitBagWriter
w = SplitBagWriter(Path({out!r})).open()
for k in range({first}, {last}):
    w.write_cdr(TOPIC, MSGTYPE, 1_000 + k, _cdr(f"w{{k:03d}}", pad=400))
w.close()
"""


def _write(out: Path, first: int, last: int, fault: str = "") -> subprocess.CompletedProcess:
    env = {**os.environ, "SHM_FAULT": fault}
    code = WRITER.format(test=str(Path(__file__).parent), out=str(out), first=first, last=last)
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)


def _ids(out: Path) -> list[str]:
    from shm_ros.io.bags import read_messages
    from shm_ros.ros.recorder_node import window_id_of

    return [window_id_of(m.data) for m in read_messages(out)]


def test_window_id_is_read_from_the_cdr_without_decoding():
    from shm_ros.ros.recorder_node import window_id_of

    for frame in ("", "a", "ab", "abc", "abcd", "frame_äö"):
        for wid in ("", "w1", "2024-05-01T00:00:00Z", "x" * 37):
            assert window_id_of(_cdr(wid, frame)) == wid


def _padding(data: bytes, msg_class, msg) -> list[int]:
    """The offsets of ``data`` (``msg`` serialized) whose value does not matter: rclpy decodes ``msg``
    whatever they hold (CDR's alignment padding)."""
    from rclpy.serialization import deserialize_message

    free = []
    for i in range(4, len(data)):
        flipped = bytearray(data)
        flipped[i] ^= 0xAB
        try:
            if deserialize_message(bytes(flipped), msg_class) == msg:
                free.append(i)
        except RuntimeError:  # a length or count changed beyond the buffer
            pass
    return free


def test_results_without_a_window_id_are_recorded_once_per_content(tmp_path):
    """A posterior or verdict published again unchanged (a restarted update or explain node, a late
    joiner's redelivery, a second replay) has the key of the one already in the bag, whatever its
    bytes hold where the content is not: the alignment padding (Fast CDR leaves it as the buffer's
    memory held it, so two serializations of one message differ there when the heap held other
    data), the byte order, the header stamp. A result that differs in one field, by one ulp, has
    another key."""
    from rclpy.serialization import serialize_message
    from shm_interfaces.msg import ParameterEstimate, PosteriorSummary, Verdict

    from shm_ros.io.bag_splits import SplitBagWriter
    from shm_ros.io.typestore import typestore
    from shm_ros.ros.recorder_node import decode_cdr_lenient, record_key, recorded_keys

    kinds = {"/shm/posterior": "shm_interfaces/msg/PosteriorSummary", "/shm/verdict": "shm_interfaces/msg/Verdict"}

    def posterior(mean: float = 1.0, name: str = "k") -> PosteriorSummary:
        return PosteriorSummary(n_windows=4, parameters=[ParameterEstimate(name=name, mean=mean)])

    def garbage_in_padding(msg) -> bytes:
        data = serialize_message(msg)
        free = _padding(data, type(msg), msg)
        assert len(free) >= 3, free  # the test must reach some padding
        dirty = bytearray(data)
        for i in free:
            dirty[i] = 0xAB
        assert bytes(dirty) != data
        return bytes(dirty)

    def big_endian(data: bytes, msgtype: str) -> bytes:
        ts = typestore()
        msg = decode_cdr_lenient(ts, msgtype, data)  # (a published one may run on past its last field)
        out = bytes(ts.serialize_cdr(msg, msgtype, little_endian=False))
        assert out[1] == 0 and out != data
        return out

    verdict = Verdict(summary="mode 2 unmodelled")
    published = {"/shm/posterior": serialize_message(posterior()), "/shm/verdict": serialize_message(verdict)}
    w = SplitBagWriter(tmp_path / "out").open()
    for t, (topic, data) in enumerate(published.items()):
        w.write_cdr(topic, kinds[topic], t + 1, data)
    w.write_cdr(TOPIC, MSGTYPE, 3, _cdr("w1"))
    w.close()
    keys = recorded_keys(tmp_path / "out")
    assert len(keys) == 3 and (TOPIC, "w1") in keys
    stamped = posterior()
    stamped.header.stamp.sec, stamped.header.stamp.nanosec = 1_714_521_600, 5
    for topic, msg, extra in (("/shm/posterior", posterior(), stamped), ("/shm/verdict", verdict, None)):
        again = [published[topic], garbage_in_padding(msg), big_endian(published[topic], kinds[topic])]
        if extra is not None:
            again.append(serialize_message(extra))
        for data in again:  # the same result published again: skipped
            assert (topic, record_key(kinds[topic], data)) in keys, (topic, data.hex())
    for other in (posterior(mean=float(np.nextafter(1.0, 2.0))), posterior(name="m")):
        assert ("/shm/posterior", record_key(kinds["/shm/posterior"], serialize_message(other))) not in keys
    other_verdict = serialize_message(Verdict(summary="mode 2 unmodelled", model_fits=True))
    assert ("/shm/verdict", record_key(kinds["/shm/verdict"], other_verdict)) not in keys
    assert record_key("diagnostic_msgs/msg/DiagnosticArray", b"\0\1\0\0") is None  # every one recorded


def test_a_message_sent_with_bytes_after_its_last_field_decodes_through_the_public_api():
    """rclpy (Fast CDR) sends a Verdict with 5 bytes after its last field, more than the typestore's
    ``deserialize_cdr`` accepts: the recorder's lenient decode gives the message the bytes carry; a
    message cut short, or with a wrong encapsulation, does not decode."""
    from rclpy.serialization import serialize_message
    from rosbags.serde import SerdeError
    from shm_interfaces.msg import Verdict

    from shm_ros.io.typestore import typestore
    from shm_ros.ros.recorder_node import decode_cdr_lenient

    ts, msgtype = typestore(), "shm_interfaces/msg/Verdict"
    data = serialize_message(Verdict(summary="mode 2 unmodelled"))
    with pytest.raises(SerdeError, match="size mismatch"):
        ts.deserialize_cdr(data, msgtype)
    msg = decode_cdr_lenient(ts, msgtype, data)
    assert msg is not None and msg.summary == "mode 2 unmodelled"
    assert msg.status == "" and msg.model_fits is False and len(msg.lag1_after) == 0
    assert len(ts.serialize_cdr(msg, msgtype)) < len(data)
    assert decode_cdr_lenient(ts, msgtype, data[:40]) is None
    assert decode_cdr_lenient(ts, msgtype, b"\x07\x07" + data[2:]) is None


def test_a_writer_killed_mid_write_loses_only_that_message_and_the_bag_reads_as_one(tmp_path):
    from shm_ros.io.bag_splits import SplitBagWriter, read_info
    from shm_ros.io.sources import open_source

    out = tmp_path / "bag"
    killed = _write(out, 0, 10, fault="bag:write:6")  # dies while the 6th message is flushed
    assert killed.returncode == -9, killed.stderr
    split = out / "bag_0"
    assert split.is_dir() and not (out / "metadata.yaml").exists()
    size = sum(f.stat().st_size for f in split.glob("*.mcap"))
    assert size > 5 * 16_000, "the first five messages must be on disk before the kill"
    # a second writer (the restarted recorder) takes up the split cut short, then writes its own
    w = SplitBagWriter(out).open()
    kept = [n for n in w.recovered if "cut short" in n]
    assert len(kept) == 1, w.recovered
    n_kept = int(kept[0].split("cut short, ")[1].split()[0])
    # the five flushed before the kill, and the sixth when its record reached the disk whole
    assert n_kept in (5, 6), kept
    assert w.split == out / "bag_2" or w.split == out / "bag_1"
    w.write_cdr(TOPIC, MSGTYPE, 5_000, _cdr("w100"))
    w.close()
    assert _write(out, 200, 203).returncode == 0  # and a third start, undisturbed
    info = read_info(out)
    assert info is not None and len(info["relative_file_paths"]) == 3
    assert all((out / f).exists() for f in info["relative_file_paths"])
    assert not [p for p in out.iterdir() if p.is_dir()], "no split left unmerged"
    source = open_source(out)
    assert source.note == "", f"the bag must open without salvage: {source.note}"
    ids = _ids(out)
    assert ids == [f"w{k:03d}" for k in range(n_kept)] + ["w100", "w200", "w201", "w202"]
    assert info["message_count"] == len(ids)
    assert info["topics_with_message_count"][0]["message_count"] == len(ids)


def test_a_closed_split_not_yet_merged_is_merged_once(tmp_path):
    """A crash between closing a split and listing it: the next open lists it, once."""
    from shm_ros.io.bag_splits import SplitBagWriter, read_info
    from shm_ros.io.bags import BagWriter

    out = tmp_path / "bag"
    assert _write(out, 0, 3).returncode == 0
    with BagWriter(out / "bag_1") as w:  # closed (metadata written) but never moved into the bag
        w.write_cdr(TOPIC, MSGTYPE, 2_000, _cdr("w010"))
    with SplitBagWriter(out) as w:
        assert any("closed split merged" in n for n in w.recovered)
        w.write_cdr(TOPIC, MSGTYPE, 3_000, _cdr("w020"))
    assert _ids(out) == ["w000", "w001", "w002", "w010", "w020"]
    assert read_info(out)["message_count"] == 5


def test_a_full_disk_stops_the_store_with_a_clear_error_and_keeps_what_was_stored(tmp_path, monkeypatch):
    from shm_ros.core.tracking import Tracker, TrackingConfig
    from shm_ros.core.types import ModalEstimate, Mode
    from shm_ros.errors import ShmError
    from shm_ros.io.store import TrackStore

    def est(k: int) -> ModalEstimate:
        return ModalEstimate(f"w{k}", k * 10**9, (k + 1) * 10**9, ["a"], [Mode(1.0, 0.02, np.array([1.0]))])

    tracker = Tracker(TrackingConfig(reference_windows=1))
    path = tmp_path / "track.sqlite"
    with TrackStore(path) as store:
        for k in range(3):
            store.record(est(k), tracker.add(est(k)), tracker)
        monkeypatch.setenv("SHM_FAULT", "store:enospc:1")
        with pytest.raises(ShmError, match="no space left.*w3 not stored; the 3 windows stored before are kept"):
            store.record(est(3), tracker.add(est(3)), tracker)
    with TrackStore(path) as store:
        assert store.count("estimates") == 3 and not store.has("w3")


def test_the_windows_of_a_split_being_written_are_counted(tmp_path):
    """What the graph tests wait on (``ros_helpers.graph.windows_written``): the windows a running
    recorder has written, its open split (in ``out/out_<k>/``, flushed message by message) included,
    so the wait ends with the last window instead of running to its timeout."""
    from ros_helpers.graph import windows_written

    from shm_ros.io.bag_splits import SplitBagWriter

    window = "shm_interfaces/msg/Window"
    w = SplitBagWriter(tmp_path / "out").open()
    w.write_cdr("/shm/windows", window, 1, _cdr("w1"))
    w.write_cdr(TOPIC, MSGTYPE, 2, _cdr("w1"))
    assert windows_written(tmp_path / "out") == 1  # the open split: one window, one estimate
    w.write_cdr("/shm/windows", window, 3, _cdr("w2"))
    assert windows_written(tmp_path / "out") == 2
    w.close()
    w = SplitBagWriter(tmp_path / "out").open()  # a closed split and an open one
    w.write_cdr("/shm/windows", window, 4, _cdr("w3"))
    assert windows_written(tmp_path / "out") == 3
    w.close()
