"""Damaged bag files read for what they still hold.

MCAP files cut short (a recorder that died: no summary, no closing magic) are read record by
record with the ``mcap`` package's stream reader, CRCs checked, up to where the data ends.
sqlite3 files cut short are read row by row in the order written (see :mod:`.sqlite_rows`).
Both yield every message read before the damage, then raise :class:`BagError` naming the file.
"""

from __future__ import annotations

import struct
from collections.abc import Collection, Iterator
from functools import lru_cache
from pathlib import Path

from shm_ros.io.errors import BagError
from shm_ros.io.sources.base import BagMessage, Batch, batches_of
from shm_ros.io.sources.compression import ZstdError, zstd_decompress
from shm_ros.io.sources.sqlite_rows import MessageCompression, RowOrder, SqliteSource


@lru_cache(maxsize=1)
def mcap_damage_errors() -> tuple[type[BaseException], ...]:
    """What the ``mcap`` stream reader raises where a file's data ends or is damaged:
    ``McapError`` (``EndOfFile``, bad magic, oversized record), ``ValueError`` (bad CRC,
    undecodable strings), ``struct.error`` (a record cut short), zstd's error (a damaged
    chunk; the package decompresses with ``zstandard``) and ``MemoryError`` (a damaged length
    field announcing gigabytes: the reader asks for them at once and gets nothing) or ``OverflowError``
    (one beyond what an index holds)."""
    import zstandard
    from mcap.exceptions import McapError

    return (McapError, ValueError, struct.error, zstandard.ZstdError, MemoryError, OverflowError)


class McapRecordSource:
    """MCAP files read record by record, in file order (``message_zstd``: each message is
    zstd-compressed, rosbag2's per-message compression)."""

    def __init__(self, path: Path, files: list[Path], note: str = "", message_zstd: bool = False) -> None:
        self.path = path
        self.files = files
        self.note = note
        self.message_zstd = message_zstd

    def topics(self) -> dict[str, str]:
        """The channels declared before the data ends (the damage itself is left to
        :meth:`messages` to report)."""
        from mcap.records import Channel, Schema

        out: dict[str, str] = {}
        for f in self.files:
            schemas: dict[int, str] = {}
            try:
                for rec in self._records(f):
                    if isinstance(rec, Schema):
                        schemas[rec.id] = rec.name
                    elif isinstance(rec, Channel):
                        out.setdefault(rec.topic, schemas.get(rec.schema_id, ""))
            except mcap_damage_errors():
                continue
        return out

    def messages(self, topics: Collection[str] | None = None) -> Iterator[BagMessage]:
        from mcap.records import Channel, Message, Schema

        wanted = None if topics is None else set(topics)
        for f in self.files:
            schemas: dict[int, str] = {}
            channels: dict[int, tuple[str, str]] = {}
            try:
                for rec in self._records(f):
                    if isinstance(rec, Message):
                        ch = channels.get(rec.channel_id)
                        if ch is not None and (wanted is None or ch[0] in wanted):
                            yield BagMessage(ch[0], ch[1], int(rec.log_time), self._payload(rec.data, f))
                    elif isinstance(rec, Schema):
                        schemas[rec.id] = rec.name
                    elif isinstance(rec, Channel):
                        channels[rec.id] = (rec.topic, schemas.get(rec.schema_id, ""))
            except mcap_damage_errors() as exc:
                raise BagError(f"{f}: damaged or truncated MCAP ({type(exc).__name__} {exc})") from exc

    def batches(self, topics: Collection[str] | None = None) -> Iterator[Batch]:
        return batches_of(self.messages(topics))

    @staticmethod
    def _records(f: Path) -> Iterator[object]:
        from mcap.stream_reader import StreamReader

        with open(f, "rb") as fh:
            yield from StreamReader(fh, validate_crcs=True).records

    def _payload(self, data: bytes, f: Path) -> bytes:
        if not self.message_zstd:
            return bytes(data)
        try:
            return zstd_decompress(data)
        except ZstdError as exc:
            raise BagError(f"{f}: damaged compressed message ({exc})") from exc


def salvage_sqlite(path: Path, files: list[Path], note: str, damage: str = "") -> SqliteSource:
    """sqlite3 files read row by row in the order written, per-message zstd recognised by its
    magic number; ``damage`` is raised after the last readable row (see :class:`SqliteSource`)."""
    return SqliteSource(path, files, RowOrder.WRITTEN, MessageCompression.DETECT, note=note, damage=damage)
