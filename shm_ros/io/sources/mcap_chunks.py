"""Complete MCAP files read a whole chunk at a time (the fast path for ``ros2 bag record`` bags).

Each chunk is located through the file's summary (chunk indexes), decompressed, and its message
records found with numpy (a chunk of equal-size messages is one run of equal records). Chunks may
overlap in time (several files, or a writer that did not order them): the messages of a chunk are
held and released, in receive order, once no later chunk can hold an earlier message.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Collection, Iterator
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.io.errors import BagError
from shm_ros.io.sources.base import BagMessage, Batch, TopicMessages, messages_of
from shm_ros.io.sources.compression import Lz4Error, ZstdError, lz4_decompress, zstd_decompress

MAGIC = b"\x89MCAP0\r\n"
_OP_MESSAGE = 5
_OP_CHUNK = 6
_REC_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = 22  # channel id (2) + sequence (4) + log time (8) + publish time (8)


@dataclass
class McapFile:
    """What the summary of one MCAP file says (see :func:`inspect_mcap`)."""

    path: Path
    problem: str = ""  # why the file cannot be read through its summary ("" when it can)
    channels: dict[int, tuple[str, str]] = field(default_factory=dict)  # id -> (topic, msgtype)
    chunk_indexes: list[Any] = field(default_factory=list)
    unchunked: bool = False  # messages outside chunks (not indexed per chunk)
    cdr: bool = True  # every channel's messages are CDR


def inspect_mcap(path: Path) -> McapFile:
    """The summary of ``path``, or the ``problem`` that says why it has none usable: a file
    without its closing magic was cut short (a recorder that died), one whose summary cannot be
    parsed is damaged there."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(len(MAGIC))
        if head != MAGIC:
            return McapFile(path, problem=f"{path}: not an MCAP file (bad magic)")
        fh.seek(max(size - len(MAGIC), 0))
        if size < 2 * len(MAGIC) or fh.read(len(MAGIC)) != MAGIC:
            return McapFile(path, problem=f"{path}: truncated MCAP (no closing magic)")
        fh.seek(0)
        try:
            summary = make_reader(fh).get_summary()
        except (McapError, struct.error, ValueError) as exc:  # the mcap package's parse errors
            return McapFile(path, problem=f"{path}: damaged MCAP summary ({type(exc).__name__}: {exc})")
    if summary is None:
        return McapFile(path, problem=f"{path}: MCAP without a summary section")
    schemas = {k: v.name for k, v in summary.schemas.items()}
    info = McapFile(path)
    for cid, ch in summary.channels.items():
        info.channels[cid] = (ch.topic, schemas.get(ch.schema_id, ""))
        info.cdr &= ch.message_encoding == "cdr"
    info.chunk_indexes = list(summary.chunk_indexes)
    stats = summary.statistics
    info.unchunked = not info.chunk_indexes and bool(stats and stats.message_count)
    return info


class McapChunkSource:
    """Complete, chunked MCAP files with CDR messages not compressed one by one."""

    def __init__(self, path: Path, files: list[McapFile], note: str = "") -> None:
        self.path = path
        self.files = files
        self.note = note

    def topics(self) -> dict[str, str]:
        return {topic: msgtype for f in self.files for topic, msgtype in f.channels.values()}

    def messages(self, topics: Collection[str] | None = None) -> Iterator[BagMessage]:
        return messages_of(self.batches(topics))

    def batches(self, topics: Collection[str] | None = None) -> Iterator[Batch]:
        wanted = None if topics is None else set(topics)
        plan = sorted(((int(ci.message_start_time), k, int(ci.chunk_start_offset), ci)
                       for k, f in enumerate(self.files) for ci in f.chunk_indexes),
                      key=lambda p: p[:3])
        held: dict[str, list[TopicMessages]] = {}
        with ExitStack() as stack:
            handles = [stack.enter_context(open(f.path, "rb")) for f in self.files]
            for i, (_, k, offset, ci) in enumerate(plan):
                f = self.files[k]
                fh = handles[k]
                fh.seek(offset)
                record = fh.read(int(ci.chunk_length))
                channels = f.channels if wanted is None else \
                    {c: tm for c, tm in f.channels.items() if tm[0] in wanted}
                try:
                    runs = decode_chunk(record, channels, f"{f.path} (chunk at byte {offset})")
                except BagError:  # what earlier chunks held is yielded before the error
                    yield Batch.of(_release(held, None), None)
                    raise
                for run in runs:
                    held.setdefault(run.topic, []).append(run)
                nxt = plan[i + 1][0] if i + 1 < len(plan) else None
                yield Batch.of(_release(held, nxt), nxt)


def _release(held: dict[str, list[TopicMessages]], before: int | None) -> list[TopicMessages]:
    """Take out of ``held`` the messages received before ``before`` (all when None), per topic."""
    out = []
    for topic in list(held):
        now, keep = [], []
        for part in held[topic]:
            if before is None or int(part.log_ns[-1]) < before:
                now.append(part)
            elif int(part.log_ns[0]) < before:
                cut = int(np.searchsorted(part.log_ns, before, side="left"))
                now.append(part.take(np.arange(cut)))
                keep.append(part.take(np.arange(cut, len(part))))
            else:
                keep.append(part)
        if now:
            out.append(TopicMessages.merge(now))
        if keep:
            held[topic] = keep
        else:
            del held[topic]
    return out


def decode_chunk(record: bytes, channels: dict[int, tuple[str, str]], where: str) -> list[TopicMessages]:
    """The messages of one MCAP chunk record on ``channels``, per channel in receive order.

    Raises :class:`BagError` naming ``where`` when the chunk is damaged.
    """
    data = _chunk_records(record, where)
    buf = np.frombuffer(data, dtype=np.uint8)
    pos_list: list[np.ndarray] = []
    len_list: list[np.ndarray] = []
    for op, positions, length in _walk_records(data, buf, where):
        if op == _OP_MESSAGE:
            if length < _MESSAGE_HEAD:
                raise BagError(f"{where}: message record of {length} bytes")
            pos_list.append(positions)
            len_list.append(np.full(positions.size, length - _MESSAGE_HEAD, np.int64))
    if not pos_list:
        return []
    content = np.concatenate(pos_list) + 9  # start of each message record's content
    lengths = np.concatenate(len_list)
    cids = _gather(buf, content, 2).view("<u2")[:, 0].astype(np.int64)
    logs = _gather(buf, content + 6, 8).view("<u8")[:, 0].astype(np.int64)
    starts = content + _MESSAGE_HEAD
    runs = []
    for cid in np.unique(cids).tolist():
        channel = channels.get(cid)
        if channel is None:
            continue
        sel = np.flatnonzero(cids == cid)
        sel = sel[np.argsort(logs[sel], kind="stable")]
        runs.append(TopicMessages(channel[0], channel[1], logs[sel], buf, starts[sel], lengths[sel]))
    return runs


def _gather(buf: np.ndarray, starts: np.ndarray, width: int) -> np.ndarray:
    """``(len(starts), width)`` bytes of ``buf`` starting at each of ``starts``."""
    return np.ascontiguousarray(buf[starts[:, None] + np.arange(width)])


def _walk_records(data: bytes, buf: np.ndarray, where: str) -> Iterator[tuple[int, np.ndarray, int]]:
    """``(opcode, record positions, content length)`` of the records in ``data``, grouped in runs
    of equal records (a chunk of equal-size messages is one run, found with one numpy check)."""
    pos, n = 0, len(data)
    unpack_head = _REC_HEAD.unpack_from
    while pos < n:
        if pos + 9 > n:
            raise BagError(f"{where}: record header cut off at byte {pos} of the chunk")
        op, ln = unpack_head(data, pos)
        size = 9 + ln
        if pos + size > n:
            raise BagError(f"{where}: record at byte {pos} runs past the end of the chunk")
        m = (n - pos) // size
        if m > 4:
            P = pos + np.arange(m, dtype=np.int64) * size
            good = (buf[P] == op) & (_gather(buf, P + 1, 8).view("<u8")[:, 0] == ln)
            run = m if good.all() else int(np.argmin(good))
            yield op, P[:run], ln
            pos += run * size
        else:
            yield op, np.asarray([pos], np.int64), ln
            pos += size


def _chunk_records(record: bytes, where: str) -> bytes:
    """The (decompressed) records inside one MCAP chunk record."""
    try:
        op, _ = _REC_HEAD.unpack_from(record, 0)
        if op != _OP_CHUNK:
            raise BagError(f"{where}: not a chunk record (opcode {op})")
        pos = 9 + 8 + 8
        size, crc = struct.unpack_from("<QI", record, pos)
        pos += 8 + 4
        (clen,) = struct.unpack_from("<I", record, pos)
        compression = record[pos + 4:pos + 4 + clen].decode()
        pos += 4 + clen
        (rlen,) = struct.unpack_from("<Q", record, pos)
        data = record[pos + 8:pos + 8 + rlen]
        if len(data) != rlen:
            raise BagError(f"{where}: chunk cut short ({len(data)} of {rlen} bytes)")
        if compression == "":
            out = data
        elif compression == "zstd":
            out = zstd_decompress(data)
        elif compression == "lz4":
            out = lz4_decompress(data)
        else:
            raise BagError(f"{where}: unknown chunk compression {compression!r}")
    except (struct.error, UnicodeDecodeError, ZstdError, Lz4Error) as exc:  # damaged bytes
        raise BagError(f"{where}: damaged chunk ({type(exc).__name__}: {exc})") from exc
    if len(out) != size:
        raise BagError(f"{where}: chunk holds {len(out)} bytes, its header says {size}")
    if crc and zlib.crc32(out) != crc:  # 0: the writer did not compute one
        raise BagError(f"{where}: damaged chunk (CRC mismatch)")
    return out
