"""rosbag2 sqlite3 files read with the standard library's ``sqlite3``, rows in batches.

A bag with its ``metadata.yaml`` is read in receive order (``ORDER BY timestamp``). A bag without
it (a recorder that was killed) or with a damaged database is read in the order the rows were
written (``rowid``), from an immutable connection: that order needs no index, so every row stored
before the damage is read, and rosbag2 writes rows as it receives them.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Collection, Iterator
from enum import Enum
from pathlib import Path

from shm_ros.io.errors import BagError
from shm_ros.io.sources.base import BagMessage, Batch, TopicMessages, messages_of
from shm_ros.io.sources.compression import ZSTD_MAGIC, ZstdError, zstd_decompress

#: Rows fetched (and handed on) together.
BATCH_ROWS = 8192


class RowOrder(Enum):
    RECEIVED = "SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp, id"
    WRITTEN = "SELECT topic_id, timestamp, data FROM messages ORDER BY rowid"


class MessageCompression(Enum):
    NONE = "none"
    ZSTD = "zstd"  # every message (metadata.yaml: compression_mode message, format zstd)
    DETECT = "detect"  # by each message's magic number (no metadata to say)


class SqliteSource:
    """Messages of rosbag2 sqlite3 files; ``damage`` (naming the file) is raised as a
    :class:`BagError` once every readable row has been yielded, for a file known to be damaged
    even if reading it met no error."""

    def __init__(self, path: Path, files: list[Path], order: RowOrder,
                 compression: MessageCompression = MessageCompression.NONE, note: str = "",
                 damage: str = "") -> None:
        self.path = path
        self.files = files
        self.order = order
        self.compression = compression
        self.note = note
        self.damage = damage

    def topics(self) -> dict[str, str]:
        out: dict[str, str] = {}
        for f in self.files:
            con = self._connect(f)
            try:
                out.update(self._topics(con, f).values())
            finally:
                con.close()
        return out

    def messages(self, topics: Collection[str] | None = None) -> Iterator[BagMessage]:
        return messages_of(self.batches(topics))

    def batches(self, topics: Collection[str] | None = None) -> Iterator[Batch]:
        wanted = None if topics is None else set(topics)
        for f in self.files:
            con = self._connect(f)
            try:
                names = self._topics(con, f)
                rows: list[tuple[int, int, bytes]] = []
                try:
                    # row by row (not fetchmany, which loses its rows when it meets damage)
                    for row in con.execute(self.order.value):  # the order's whole (fixed) query
                        rows.append(row)
                        if len(rows) >= BATCH_ROWS:
                            yield self._batch(rows, names, wanted, f)
                            rows = []
                except sqlite3.DatabaseError as exc:  # malformed pages, a file cut short
                    if rows:
                        yield self._batch(rows, names, wanted, f)
                    raise BagError(f"{f}: damaged sqlite3 bag file ({exc})") from exc
                if rows:
                    yield self._batch(rows, names, wanted, f)
            finally:
                con.close()
        if self.damage:
            raise BagError(self.damage)

    def _connect(self, f: Path) -> sqlite3.Connection:
        # immutable: no locking and no journal lookup, for a file a dead recorder left behind
        mode = "ro&immutable=1" if self.order is RowOrder.WRITTEN else "ro"
        try:
            return sqlite3.connect(f"file:{f}?mode={mode}", uri=True)
        except sqlite3.Error as exc:
            raise BagError(f"{f}: cannot open sqlite3 bag file ({exc})") from exc

    @staticmethod
    def _topics(con: sqlite3.Connection, f: Path) -> dict[int, tuple[str, str]]:
        try:
            return {int(i): (str(n), str(t)) for i, n, t in con.execute("SELECT id, name, type FROM topics")}
        except sqlite3.DatabaseError as exc:
            raise BagError(f"{f}: damaged sqlite3 bag file ({exc})") from exc

    def _batch(self, rows: list[tuple[int, int, bytes]], names: dict[int, tuple[str, str]],
               wanted: set[str] | None, f: Path) -> Batch:
        groups: dict[int, tuple[list[int], list[bytes]]] = {}
        for tid, t_ns, data in rows:
            group = groups.get(tid)
            if group is None:
                group = groups[tid] = ([], [])
            group[0].append(t_ns)
            group[1].append(data)
        runs = []
        for tid, (log, datas) in groups.items():
            name = names.get(int(tid))
            if name is None or (wanted is not None and name[0] not in wanted):
                continue
            if self.compression is not MessageCompression.NONE:
                datas = [self._decompress(bytes(d), f) for d in datas]
            runs.append(TopicMessages.from_bytes(name[0], name[1], log, datas))
        return Batch.of(runs, int(rows[-1][1]))

    def _decompress(self, data: bytes, f: Path) -> bytes:
        if self.compression is MessageCompression.DETECT and data[:4] != ZSTD_MAGIC:
            return data
        try:
            return zstd_decompress(data)
        except ZstdError as exc:
            raise BagError(f"{f}: damaged compressed message ({exc})") from exc


def sqlite_damage(f: Path) -> str:
    """Why ``f`` is known to be damaged without reading its rows ("" when nothing is seen): a
    file shorter than the page count in its header was cut short."""
    with open(f, "rb") as fh:
        head = fh.read(100)
    if len(head) < 100 or not head.startswith(b"SQLite format 3\x00"):
        return f"{f}: not an sqlite3 database (bad header)"
    page = int.from_bytes(head[16:18], "big")
    page = 65536 if page == 1 else page
    pages = int.from_bytes(head[28:32], "big")
    valid = head[24:28] == head[92:96]  # the page count is valid only when these agree
    size = f.stat().st_size
    if valid and pages and size < page * pages:
        return f"{f}: sqlite3 bag file cut short ({size} of {page * pages} bytes)"
    return ""
