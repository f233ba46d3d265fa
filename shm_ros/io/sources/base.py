"""What every bag back end gives: raw CDR messages by topic, with their log (receive) times.

A source yields :class:`Batch` es. Within a batch each topic's messages are one
:class:`TopicMessages` (one buffer, receive order), so that a reader can decode a topic's
messages together (see :mod:`shm_ros.io.imu_cdr`). Batches come in receive order: once a batch
is yielded, every message received before its ``complete_before_ns`` has been yielded, which is
what lets the ingest cut windows while it reads.

A source raises :class:`~shm_ros.io.errors.BagError` naming the file when its data ends early or is
damaged, after yielding every message read before that point; it never switches to another way
of reading once it has yielded something.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from shm_ros.io.errors import BagError
from shm_ros.io.typestore import typestore


@dataclass
class BagMessage:
    """One raw message: topic, type, receive time and CDR bytes (``decode()`` when needed)."""

    topic: str
    msgtype: str
    receive_ns: int
    data: bytes

    def decode(self) -> Any:
        return typestore().deserialize_cdr(self.data, self.msgtype)


#: Messages gathered into one batch by the sources that read one message at a time.
BATCH_MESSAGES = 4096


@dataclass(frozen=True)
class TopicMessages:
    """Messages of one topic, in receive order: message ``i`` is
    ``buf[starts[i]:starts[i] + lengths[i]]`` (``buf`` is uint8), received at ``log_ns[i]``."""

    topic: str
    msgtype: str
    log_ns: np.ndarray  # (n,) int64
    buf: np.ndarray  # uint8
    starts: np.ndarray  # (n,) int64
    lengths: np.ndarray  # (n,) int64

    @classmethod
    def from_bytes(cls, topic: str, msgtype: str, log_ns: Sequence[int],
                   datas: Sequence[bytes]) -> TopicMessages:
        lengths = np.fromiter((len(d) for d in datas), np.int64, len(datas))
        starts = np.concatenate(([0], np.cumsum(lengths)[:-1])).astype(np.int64)
        buf = np.frombuffer(b"".join(datas), dtype=np.uint8)
        return cls(topic, msgtype, np.asarray(log_ns, dtype=np.int64), buf, starts, lengths)

    def __len__(self) -> int:
        return int(self.log_ns.size)

    def data(self, i: int) -> bytes:
        s = int(self.starts[i])
        return self.buf[s:s + int(self.lengths[i])].tobytes()

    def take(self, idx: np.ndarray) -> TopicMessages:
        """The messages at ``idx`` (indices or a mask), sharing this buffer."""
        return TopicMessages(self.topic, self.msgtype, self.log_ns[idx], self.buf, self.starts[idx],
                             self.lengths[idx])

    @staticmethod
    def merge(parts: Sequence[TopicMessages]) -> TopicMessages:
        """Messages of one topic from several buffers, in receive order (stable for ties)."""
        if len(parts) == 1:
            return parts[0]
        bufs, starts, offset = [], [], 0
        for p in parts:
            # the bytes of p's messages, packed: one ragged gather
            total = int(p.lengths.sum())
            first = np.cumsum(p.lengths) - p.lengths
            idx = np.repeat(p.starts - first, p.lengths) + np.arange(total)
            bufs.append(p.buf[idx])
            starts.append(first + offset)
            offset += total
        log = np.concatenate([p.log_ns for p in parts])
        merged = TopicMessages(parts[0].topic, parts[0].msgtype, log, np.concatenate(bufs),
                               np.concatenate(starts), np.concatenate([p.lengths for p in parts]))
        return merged.take(np.argsort(log, kind="stable"))


@dataclass(frozen=True)
class Batch:
    """Messages read together, one :class:`TopicMessages` per topic (ordered by their first
    receive time); every message received before ``complete_before_ns`` has been yielded once
    this batch is (None: nothing is promised until the end of the bag)."""

    runs: list[TopicMessages]
    complete_before_ns: int | None

    @classmethod
    def of(cls, runs: Iterable[TopicMessages], complete_before_ns: int | None) -> Batch:
        kept = [r for r in runs if len(r)]
        kept.sort(key=lambda r: int(r.log_ns[0]))
        return cls(kept, complete_before_ns)

    def __len__(self) -> int:
        return sum(len(r) for r in self.runs)


class MessageSource(Protocol):
    """One bag read by one back end (see :func:`~shm_ros.io.sources.open_source`)."""

    #: The bag (directory or file).
    path: Path
    #: Empty for a bag read the normal way; otherwise why it is read this way (no metadata,
    #: damaged file), naming the file, for the reader to pass on as a warning.
    note: str

    def topics(self) -> dict[str, str]:
        """``{topic: msgtype}`` of the bag."""
        ...

    def batches(self, topics: Collection[str] | None = None) -> Iterator[Batch]:
        """The messages (of ``topics``, all when None) in receive order, batch by batch."""
        ...

    def messages(self, topics: Collection[str] | None = None) -> Iterator[BagMessage]:
        """The same messages one by one, in receive order."""
        ...


def messages_of(batches: Iterable[Batch]) -> Iterator[BagMessage]:
    """The messages of ``batches`` one by one, in receive order (ties: in batch order)."""
    for batch in batches:
        if not batch.runs:
            continue
        if len(batch.runs) == 1:
            run = batch.runs[0]
            for i, t in enumerate(run.log_ns.tolist()):
                yield BagMessage(run.topic, run.msgtype, t, run.data(i))
            continue
        log = np.concatenate([r.log_ns for r in batch.runs])
        which = np.concatenate([np.full(len(r), k) for k, r in enumerate(batch.runs)])
        index = np.concatenate([np.arange(len(r)) for r in batch.runs])
        for j in np.argsort(log, kind="stable").tolist():
            run = batch.runs[int(which[j])]
            yield BagMessage(run.topic, run.msgtype, int(log[j]), run.data(int(index[j])))


def batches_of(messages: Iterable[BagMessage], size: int = BATCH_MESSAGES) -> Iterator[Batch]:
    """``messages`` (in receive order) gathered ``size`` at a time into batches; each promises
    that everything received before its last message has been yielded."""
    groups: dict[str, tuple[str, list[int], list[bytes]]] = {}
    n, last = 0, 0
    try:
        for m in messages:
            group = groups.get(m.topic)
            if group is None:
                group = groups[m.topic] = (m.msgtype, [], [])
            group[1].append(m.receive_ns)
            group[2].append(m.data)
            n += 1
            last = m.receive_ns
            if n >= size:
                yield _batch(groups, last)
                groups, n = {}, 0
    except BagError:
        if n:  # what was read before the damage, then the error
            yield _batch(groups, None)
        raise
    if n:
        yield _batch(groups, None)


def _batch(groups: dict[str, tuple[str, list[int], list[bytes]]], complete_before_ns: int | None) -> Batch:
    return Batch.of((TopicMessages.from_bytes(topic, msgtype, log, datas)
                     for topic, (msgtype, log, datas) in groups.items()), complete_before_ns)
