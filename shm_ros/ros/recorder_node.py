"""recorder: writes pipeline topics (CDR as received) into an output bag, under their fully
qualified names (the node's namespace resolves the relative ones).

Restarts lose and duplicate nothing: each start writes a new split of the same bag
(:class:`~shm_ros.io.bag_splits.SplitBagWriter`: a split cut short by a crash is taken up first,
every message is on disk once written), and a message that carries a window id (windows, modal
estimates, tracked modes, predictions) is recorded once per topic and window: one published
again after a restart upstream, or re-published for a second replay, is counted and skipped. The
results without a window id (posteriors, verdicts: latched) are recorded once per topic and content:
the same result published again (by a restarted update or explain node that redid its run, to a
restarted recorder as a late joiner, by a second replay) is skipped; a different one is recorded. A
full disk stops the recording with an error naming the bag; what was recorded is kept.
"""

from __future__ import annotations

import enum
import errno
import hashlib
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from shm_ros.core.config import option
from shm_ros.io.atomic import DiskFullError
from shm_ros.io.bag_splits import SplitBagWriter
from shm_ros.io.faults import disk_full_point
from shm_ros.ros import topics
from shm_ros.ros.managed import ManagedNode
from shm_ros.ros.node_main import spin
from shm_ros.ros.params import load_config
from shm_ros.ros.qos import latched_qos, pipeline_qos, stream_qos

DEFAULT_TOPICS = [topics.WINDOWS, topics.MODAL_ESTIMATES, topics.TRACKED_MODES, topics.POSTERIOR,
                  topics.PREDICTION, topics.VERDICT, topics.DIAGNOSTICS]
LATCHED = {topics.POSTERIOR, topics.VERDICT}
STREAMS = {topics.WINDOWS, topics.MODAL_ESTIMATES, topics.TRACKED_MODES}
#: message types whose fields begin with ``std_msgs/Header header`` and ``string window_id``
WINDOW_KEYED = {"shm_interfaces/msg/Window", "shm_interfaces/msg/ModalEstimate", "shm_interfaces/msg/TrackedModes",
                "shm_interfaces/msg/ResponsePrediction"}
#: results without a window id: recorded once per content (:func:`canonical_cdr`)
CONTENT_KEYED = {"shm_interfaces/msg/PosteriorSummary", "shm_interfaces/msg/Verdict"}


def window_id_of(data: bytes) -> str:
    """The ``window_id`` of a CDR message of a :data:`WINDOW_KEYED` type, read without decoding
    the rest (a window's samples)."""
    end = "<" if data[1] & 1 else ">"  # encapsulation: CDR little or big endian
    off = 4 + 8  # encapsulation header, header.stamp (sec, nanosec)
    (n,) = struct.unpack_from(f"{end}I", data, off)  # header.frame_id, with its NUL
    off = 4 + ((off + 4 + n - 4 + 3) & ~3)  # strings are 4-aligned (from after the encapsulation)
    (n,) = struct.unpack_from(f"{end}I", data, off)
    return data[off + 4:off + 3 + n].decode("utf-8", "replace")


def record_key(msgtype: str, data: bytes) -> str | None:
    """What a message is recorded once by (with its topic): the window id of a :data:`WINDOW_KEYED`
    message, the digest of a :data:`CONTENT_KEYED` one; None: every message is recorded."""
    if msgtype in WINDOW_KEYED:
        return window_id_of(data)
    if msgtype in CONTENT_KEYED:
        return "sha256:" + hashlib.sha256(canonical_cdr(msgtype, data)).hexdigest()
    return None


def canonical_cdr(msgtype: str, data: bytes) -> bytes:
    """The content of a CDR message of a :data:`CONTENT_KEYED` type as bytes that depend on its
    fields only: decoded and encoded again (little endian, alignment padding zero) with the header
    stamp cleared. The serialized message a publisher sends is not such bytes: Fast CDR leaves the
    alignment padding as the buffer held it (heap garbage), and may send bytes beyond the last
    field, so one result published twice, or by a restarted node, may differ there; and a stamp
    set at publishing says when, not what. Bytes that do not decode are their own content."""
    from dataclasses import replace

    from shm_ros.io.typestore import typestore

    ts = typestore()
    msg: Any = decode_cdr_lenient(ts, msgtype, data)
    if msg is None:  # malformed: keyed by its bytes
        return bytes(data)
    if (header := getattr(msg, "header", None)) is not None:
        msg = replace(msg, header=replace(header, stamp=replace(header.stamp, sec=0, nanosec=0)))
    return bytes(ts.serialize_cdr(msg, msgtype))


#: at most this many bytes after a message's last field are taken as the sender's end padding
MAX_TRAILING = 64


def decode_cdr_lenient(ts: Any, msgtype: str, data: bytes) -> object | None:
    """``data`` decoded by the typestore's public ``deserialize_cdr``, bytes a sender put after the
    last field (Fast CDR ends a message at its buffer's alignment: 5 bytes after a Verdict's last
    field, where the typestore allows 3) left out; None when it does not decode. The typestore
    refuses more than 3 bytes after the end ("size mismatch", an error without a cause); the message
    is then decoded from ``data`` cut one byte shorter until it is accepted: the first length
    accepted still holds every field (the end of the last field is at most 3 bytes before it), so
    the message is the one the whole of ``data`` carries."""
    from rosbags.serde import SerdeError

    if len(data) < 4 or bytes(data[:2]) not in (b"\x00\x00", b"\x00\x01"):
        return None
    view = memoryview(data)
    for end in range(len(data), max(len(data) - MAX_TRAILING, 4) - 1, -1):
        try:
            return ts.deserialize_cdr(view[:end], msgtype)
        except SerdeError as exc:
            if exc.__cause__ is not None:  # a field does not decode (not bytes after the end)
                return None
        except IndexError:  # a length beyond the buffer the typestore does not check
            return None
    return None


class Storage(enum.StrEnum):
    MCAP = "mcap"  # what `ros2 bag record` writes
    SQLITE3 = "sqlite3"


@dataclass
class RecorderNodeConfig:
    output: str = option("shm_output_bag", "output bag directory")
    topics: list[str] = option(DEFAULT_TOPICS, "topics to record (pipeline topics of known type)")
    storage: str = option(Storage.MCAP.value, "bag storage", choices=Storage)


class RecorderNode(ManagedNode):
    """Parameters: the options of :class:`RecorderNodeConfig`."""

    kind = "recorder"

    def setup(self) -> None:
        settings = load_config(self, RecorderNodeConfig)
        out = Path(settings.output)
        self.out = out
        self.writer: SplitBagWriter | None = SplitBagWriter(out, storage=settings.storage).open()
        for note in self.writer.recovered:
            self.get_logger().warning(f"{out}: {note}")
        # (topic, window id or digest) of what the bag holds already, earlier splits included
        self.recorded = recorded_keys(out)
        self.count = 0
        self.duplicates = 0
        self.stopped = ""  # why recording stopped (a full disk)
        self.diag.summarize(lambda: (
            "error" if self.stopped else "ok", self.stopped or f"{self.count} messages recorded to {out}",
            {"messages": self.count, "output": out, "duplicates_skipped": self.duplicates,
             "split": self.writer.split.name if self.writer and self.writer.split else ""}))
        for topic in settings.topics:
            msgtype = topics.type_of(topic)
            if msgtype is None:
                self.get_logger().error(f"parameter topics: no known type for {topic!r}; not recorded")
                continue
            name = topics.relative(topic)
            qos = (latched_qos() if name in LATCHED else
                   stream_qos() if name in STREAMS else pipeline_qos())
            # the bag holds the fully qualified name (/bridge_a/shm/windows), as `ros2 bag record` writes it
            self.create_subscription(topics.message_class(msgtype), topic,
                                     self._writer_for(self.resolve_topic_name(topic), msgtype), qos, raw=True)
        self.get_logger().info(f"recording to {out}")

    def _writer_for(self, topic: str, msgtype: str):
        keyed = msgtype in WINDOW_KEYED or msgtype in CONTENT_KEYED

        def write(data: bytes) -> None:
            if self.writer is None:
                return
            if keyed:
                key = (topic, record_key(msgtype, data))
                if key in self.recorded:
                    self.duplicates += 1
                    return
            try:
                disk_full_point(self.get_name(), self.out)
                self.writer.write_cdr(topic, msgtype, self.get_clock().now().nanoseconds, data)
            except OSError as exc:
                if exc.errno != errno.ENOSPC:
                    raise
                self._disk_full(exc)
            if keyed:
                self.recorded.add(key)
            self.count += 1
        return write

    def _disk_full(self, exc: OSError) -> None:
        """Stop recording, say so, and end the node with the error (the supervisor stops the graph)."""
        self.stopped = (f"{self.out}: no space left on the device: recording stopped; the {self.count} "
                        "messages recorded before are kept")
        self.get_logger().error(self.stopped)
        self.diag.report("error", self.stopped, "recording")
        self.diag.publish()
        self.teardown()
        raise DiskFullError(errno.ENOSPC, self.stopped) from exc

    def teardown(self) -> None:
        """Close the bag (shutdown, cleanup): what was recorded stays readable. A split that cannot
        be closed (a full disk) stays as written; the next start of a recorder on this bag takes it up."""
        writer, self.writer = self.writer, None
        if writer is None:
            return
        try:
            writer.close()
        except OSError as exc:
            if exc.errno != errno.ENOSPC:
                raise
            self.get_logger().error(f"{self.out}: no space left to close {writer.split}: it is kept as "
                                    "written and taken up when a recorder next opens the bag")
            return
        self.get_logger().info(f"recorded {self.count} messages ({self.duplicates} duplicates skipped)")


def recorded_keys(path: Path) -> set[tuple[str, str | None]]:
    """(topic, :func:`record_key`) of every window- or content-keyed message in the bag at ``path``
    (none if no bag)."""
    from shm_ros.io.bag_splits import read_info
    from shm_ros.io.bags import read_messages

    info = read_info(path) if path.is_dir() else None
    if not info or not info.get("relative_file_paths"):
        return set()
    keyed = [t["topic_metadata"]["name"] for t in info.get("topics_with_message_count") or []
             if t["topic_metadata"]["type"] in WINDOW_KEYED | CONTENT_KEYED]
    return {(m.topic, record_key(m.msgtype, m.data)) for m in read_messages(path, keyed)} if keyed else set()


def make_node(name: str, parameters: dict[str, Any], namespace: str = "") -> RecorderNode:
    return RecorderNode(name, parameters, namespace)


def main(args: list[str] | None = None) -> int:
    return spin(lambda: RecorderNode(), args)


if __name__ == "__main__":
    raise SystemExit(main())
