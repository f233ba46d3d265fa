"""Any bag ``rosbags`` reads (the generic back end): bags whose messages are compressed one by
one or whose files are compressed whole, MCAP without chunks, ROS 1 bags, other storage ids.
Messages come in ``rosbags``' receive-time order, one at a time.
"""

from __future__ import annotations

import struct
from collections.abc import Collection, Iterator
from functools import lru_cache
from pathlib import Path

from shm_ros.io.errors import BagError
from shm_ros.io.sources.base import BagMessage, Batch, batches_of
from shm_ros.io.sources.compression import ZstdError
from shm_ros.io.typestore import typestore


@lru_cache(maxsize=1)
def read_errors() -> tuple[type[BaseException], ...]:
    """What ``rosbags`` raises for a bag it cannot read or whose data is damaged.

    Its readers wrap most faults in their ``ReaderError`` s (``AnyReaderError`` when opening),
    but message iteration lets through the errors of what parses the files: ``struct.error`` and
    ``EOFError`` from its MCAP parser, ``apsw.Error`` from sqlite3, ``ZstdError`` from compressed
    messages or files, ``OSError`` from the file system. (A truncated MCAP file can also end its
    parser in a ``TypeError``; such files never reach this back end, see ``choose.py``.)
    """
    import apsw
    from rosbags.highlevel import AnyReaderError
    from rosbags.rosbag1 import ReaderError as Rosbag1ReaderError
    from rosbags.rosbag2 import ReaderError as Rosbag2ReaderError

    return (AnyReaderError, Rosbag1ReaderError, Rosbag2ReaderError, struct.error, EOFError,
            apsw.Error, ZstdError, OSError)


class RosbagsSource:
    def __init__(self, path: Path, note: str = "") -> None:
        self.path = path
        self.note = note

    def topics(self) -> dict[str, str]:
        from rosbags.highlevel import AnyReader

        try:
            with AnyReader([self.path], default_typestore=typestore()) as reader:
                return {c.topic: c.msgtype for c in reader.connections}
        except read_errors() as exc:
            raise BagError(f"{self.path}: cannot read bag: {exc}") from exc

    def messages(self, topics: Collection[str] | None = None) -> Iterator[BagMessage]:
        from rosbags.highlevel import AnyReader

        wanted = None if topics is None else set(topics)
        try:
            with AnyReader([self.path], default_typestore=typestore()) as reader:
                conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
                for conn, t_ns, raw in reader.messages(connections=conns):
                    yield BagMessage(conn.topic, conn.msgtype, int(t_ns), bytes(raw))
        except read_errors() as exc:
            raise BagError(f"{self.path}: cannot read bag: {exc}") from exc

    def batches(self, topics: Collection[str] | None = None) -> Iterator[Batch]:
        return batches_of(self.messages(topics))
