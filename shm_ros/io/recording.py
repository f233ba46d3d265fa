"""A recorded bag -> the streaming ingest core -> windows (the offline path of ``ingest``).

The same :class:`~shm_ros.core.ingest.IngestCore` runs here and in the live node: this module only
reads and decodes messages. ``sensor_msgs/Imu`` messages are decoded in batches straight from their
CDR bytes (see :func:`decode_imu_batch`), which is what makes per-sample Imu bags fast to ingest.

A damaged bag never raises: every window that the data read before the damage makes is kept and the
error, naming the bag, is reported as a diagnostic. MCAP files that lost their summary (a recorder
that died) are read record by record with the ``mcap`` package's stream reader.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.core.types import Window
from shm_ros.core.ingest import (
    ChannelMap, Diagnostic, DroppedSpan, IngestConfig, IngestCore, IngestStats, Level,
)
from shm_ros.io.bags import IMU, BagError, BagMessage, read_messages, topic_kind
from shm_ros.io.typestore import typestore

#: Imu messages decoded together (one numpy pass per batch).
IMU_BATCH = 4096


@dataclass
class IngestResult:
    windows: list[Window]
    diagnostics: list[Diagnostic]
    stats: IngestStats
    dropped: list[DroppedSpan]
    sample_rate_hz: float | None
    ignored_topics: list[str] = field(default_factory=list)
    messages: int = 0
    diagnostic_counts: dict = field(default_factory=dict)  # (code, source) -> occurrences


def channel_map_of(structure_or_map: Any) -> ChannelMap:
    """A :class:`ChannelMap` from a map, a ``StructureSpec`` or the path of a structure file."""
    if isinstance(structure_or_map, ChannelMap):
        return structure_or_map
    if isinstance(structure_or_map, (str, Path)):
        from shm_ros.io.structure import load_structure

        return ChannelMap.from_structure(load_structure(structure_or_map))
    return ChannelMap.from_structure(structure_or_map)


def windows_from_bag(path: str | Path, structure_or_channel_map: Any, window_s: float = 600.0, *,
                     config: IngestConfig | None = None) -> tuple[list[Window], list[Diagnostic]]:
    """All windows of a bag and the diagnostics found on the way (see :func:`ingest_bag`)."""
    res = ingest_bag(path, structure_or_channel_map, window_s, config=config)
    return res.windows, res.diagnostics


def ingest_bag(path: str | Path, structure_or_channel_map: Any, window_s: float = 600.0, *,
               config: IngestConfig | None = None, margin_s: float = 10.0) -> IngestResult:
    """Read a bag through :class:`IngestCore`; unrelated topics are ignored (and listed).

    ``config`` overrides every setting except ``window_s`` when given (its ``window_s`` is replaced
    by the argument). Messages come in receive-time order; a window is cut once the receive time is
    ``margin_s`` past its end (so header stamps may lag receive times by up to ``margin_s``; an
    AccelBlock longer than that widens the margin).
    """
    cmap = channel_map_of(structure_or_channel_map)
    base = IngestConfig() if config is None else config
    config = IngestConfig(**{**base.__dict__, "window_s": window_s, "max_latency_s": float("inf")})
    core = IngestCore(cmap, config)
    reader = _BagFeeder(core, Path(path), margin_s)
    reader.run()
    windows = core.flush()
    return IngestResult(windows, core.diagnostics, core.stats, core.dropped, core.sample_rate_hz,
                        sorted(reader.ignored), reader.n_messages, dict(core.diagnostic_counts))


class _BagFeeder:
    """Decodes the messages of one bag in receive order and feeds the core."""

    def __init__(self, core: IngestCore, path: Path, margin_s: float) -> None:
        self.core = core
        self.path = path
        self.margin_ns = int(margin_s * 1e9)
        self.ignored: set[str] = set()
        self.kinds: dict[str, tuple[str, str] | None] = {}
        self.imu_raw: dict[str, list[bytes]] = {}
        self.n_imu = 0
        self.n_messages = 0
        self.receive_ns = 0
        self.held_imu: dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {}
        self.held_other: list[tuple] = []
        self.ts = typestore()

    def run(self) -> None:
        try:
            done = self._run_mcap_chunks() or self._run_sqlite()
        except _Damaged as exc:
            self.flush_imu()
            self.core.report_error(str(self.path), f"{self.path}: cannot read bag: {exc.__cause__} "
                                   f"({self.n_messages} messages read before the damage were ingested)",
                                   code="bag_damaged")
            done = True
        except Exception:  # the fast paths are an optimisation only: fall back to rosbags
            done = False
        if not done:
            self._run_rosbags()
        self.flush_imu()
        if self.ignored:
            self.core.report_error(str(self.path), "ignored topics (not accelerometer/temperature "
                                   "contract topics): " + ", ".join(sorted(self.ignored)),
                                   level=Level.OK, code="ignored_topics")

    def _run_rosbags(self) -> None:
        got = 0
        try:
            for msg in read_messages(self.path):
                got += 1
                self.feed(msg)
        except BagError as exc:
            self.flush_imu()
            if got == 0 and can_salvage(self.path):
                salvaged = 0
                try:
                    for msg in salvage(self.path):
                        salvaged += 1
                        self.feed(msg)
                except BagError as exc2:
                    self.flush_imu()
                    self.core.report_error(str(self.path), f"{exc2} ({salvaged} messages read before "
                                           "the damage were ingested)", code="bag_damaged")
                else:
                    self.core.report_error(str(self.path), f"{exc}; read from its storage files directly instead",
                                           level=Level.WARN, code="bag_damaged")
            else:
                self.core.report_error(str(self.path), f"{exc} ({got} messages read before the "
                                       "damage were ingested)", code="bag_damaged")

    def _run_mcap_chunks(self) -> bool:
        """Complete, uncompressed-per-message MCAP bags: whole chunks at a time (fast path)."""
        files = _mcap_files(self.path)
        if not files:
            return False
        from mcap.reader import make_reader

        plan = []
        meta: dict[Path, dict[int, tuple[str, str]]] = {}
        for f in files:
            with open(f, "rb") as fh:
                summary = make_reader(fh).get_summary()
            if summary is None or (not summary.chunk_indexes and summary.statistics and
                                   summary.statistics.message_count):
                return False
            schemas = {k: v.name for k, v in summary.schemas.items()}
            chans = {}
            for cid, ch in summary.channels.items():
                if ch.message_encoding != "cdr":
                    return False
                chans[cid] = (ch.topic, schemas.get(ch.schema_id, ""))
            meta[f] = chans
            plan.extend((ci.message_start_time, str(f), ci) for ci in summary.chunk_indexes)
        plan.sort(key=lambda p: (p[0], p[1], p[2].chunk_start_offset))
        handles = {f: open(f, "rb") for f in files}
        try:
            for i, (_, fname, ci) in enumerate(plan):
                f = Path(fname)
                fh = handles[f]
                fh.seek(ci.chunk_start_offset)
                try:
                    self._read_chunk(_chunk_records(fh.read(ci.chunk_length)), meta[f])
                except Exception as exc:
                    if self.n_messages:
                        raise _Damaged() from exc
                    raise
                # chunks may overlap in time: release (in receive order) only what no later chunk
                # can precede
                nxt = plan[i + 1][0] if i + 1 < len(plan) else None
                self._release(None if nxt is None else int(nxt))
                if nxt is not None:
                    self.core.advance(int(nxt) - self.margin_ns)
        finally:
            for fh in handles.values():
                fh.close()
        return True

    def _run_sqlite(self) -> bool:
        """sqlite3 bags read with the standard library in batches (fast path; rows in time order)."""
        files = _bag_files(self.path, "sqlite3")
        if not files:
            return False
        import sqlite3

        conns = []
        try:
            for f in files:
                con = sqlite3.connect(f"file:{f}?mode=ro", uri=True)
                topics = {int(i): (str(n), str(t)) for i, n, t in con.execute("SELECT id, name, type FROM topics")}
                conns.append((con, topics))
        except sqlite3.Error:
            for con, _ in conns:
                con.close()
            return False  # let rosbags open it and report
        try:
            for con, topics in conns:
                try:
                    cur = con.execute("SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp, id")
                    while True:
                        rows = cur.fetchmany(8192)
                        if not rows:
                            break
                        self._feed_rows(rows, topics)
                except sqlite3.Error as exc:
                    raise _Damaged() from exc
        finally:
            for con, _ in conns:
                con.close()
        return True

    def _feed_rows(self, rows: list[tuple[int, int, bytes]], topics: dict[int, tuple[str, str]]) -> None:
        imu: dict[str, list[bytes]] = {}
        for tid, t_ns, data in rows:
            self.n_messages += 1
            topic, msgtype = topics.get(tid, ("", ""))
            kind = self._kind(topic, msgtype)
            if kind is None:
                continue
            if kind[0] == "imu":
                lst = imu.get(kind[1])
                if lst is None:
                    lst = imu[kind[1]] = []
                lst.append(data)
            else:
                for sid, datas in imu.items():
                    self.imu_raw.setdefault(sid, []).extend(datas)
                    self.n_imu += len(datas)
                imu = {}
                self.flush_imu()
                self._feed_decoded(topic, msgtype, kind[0], kind[1], bytes(data))
        for sid, datas in imu.items():
            self.imu_raw.setdefault(sid, []).extend(datas)
            self.n_imu += len(datas)
        self.flush_imu()
        self.core.advance(int(rows[-1][1]) - self.margin_ns)

    def _read_chunk(self, buf: bytes, chans: dict[int, tuple[str, str]]) -> None:
        mv = np.frombuffer(buf, dtype=np.uint8)
        pos_list: list[np.ndarray] = []
        len_list: list[np.ndarray] = []
        for op, positions, length in _walk_records(buf, mv):
            if op == 5:
                pos_list.append(positions)
                len_list.append(np.full(positions.size, length - 22, np.int64))
        if not pos_list:
            return
        P = np.concatenate(pos_list) + 9  # start of each message record's content
        L = np.concatenate(len_list)
        cids = _gather(mv, P, 2).view("<u2")[:, 0].astype(np.int64)
        logs = _gather(mv, P + 6, 8).view("<u8")[:, 0].astype(np.int64)
        starts = P + 22
        for cid in np.flatnonzero(np.bincount(cids)).tolist():
            sel = np.flatnonzero(cids == cid)
            topic, msgtype = chans.get(cid, ("", ""))
            kind = self._kind(topic, msgtype)
            self.n_messages += sel.size
            if kind is None:
                continue
            what, sid = kind
            st, ln, lg = starts[sel], L[sel], logs[sel]
            if what == "imu":
                stamps, xyz, ok = _imu_decode(mv, st, ln)
                for i in np.flatnonzero(~ok).tolist():
                    try:
                        stamps[i], xyz[i] = _imu_slow(buf[st[i]:st[i] + ln[i]], i)
                        ok[i] = True
                    except ValueError as exc:
                        self.core.report_error(f"{self.path}:{topic}", f"cannot decode Imu: {exc}")
                self.held_imu.setdefault(sid, []).append((lg[ok], stamps[ok], xyz[ok]))
            else:
                for a, b, t in zip(st.tolist(), ln.tolist(), lg.tolist()):
                    self.held_other.append((t, len(self.held_other), topic, msgtype, what, sid,
                                            buf[a:a + b]))

    def _release(self, before: int | None) -> None:
        """Feed held messages received before ``before`` (all when None), in receive order."""
        for sid in list(self.held_imu):
            parts = self.held_imu[sid]
            out, keep = [], []
            for logs, stamps, xyz in parts:
                if before is None or (logs.size and logs.max() < before):
                    out.append((logs, stamps, xyz))
                elif logs.size and logs.min() < before:
                    now = logs < before
                    out.append((logs[now], stamps[now], xyz[now]))
                    keep.append((logs[~now], stamps[~now], xyz[~now]))
                else:
                    keep.append((logs, stamps, xyz))
            if out:
                logs = np.concatenate([p[0] for p in out])
                idx = np.argsort(logs, kind="stable")
                stamps = np.concatenate([p[1] for p in out])[idx]
                xyz = np.concatenate([p[2] for p in out])[idx]
                self.core.add_imu_array(sid, stamps, xyz)
            if keep:
                self.held_imu[sid] = keep
            else:
                del self.held_imu[sid]
        if self.held_other:
            self.held_other.sort(key=lambda m: (m[0], m[1]))
            k = len(self.held_other) if before is None else \
                sum(1 for m in self.held_other if m[0] < before)
            now_o, self.held_other = self.held_other[:k], self.held_other[k:]
            for _lg, _i, topic, msgtype, what, sid, data in now_o:
                self._feed_decoded(topic, msgtype, what, sid, data)

    def _kind(self, topic: str, msgtype: str) -> tuple[str, str] | None:
        kind = self.kinds.get(topic, False)
        if kind is False:
            kind = self.kinds[topic] = topic_kind(topic, msgtype)
            if kind is None:
                self.ignored.add(f"{topic} ({msgtype})")
        return kind  # type: ignore[return-value]

    def feed(self, msg: BagMessage) -> None:
        self.n_messages += 1
        kind = self._kind(msg.topic, msg.msgtype)
        if msg.receive_ns - self.receive_ns > 1_000_000_000:
            self.flush_imu()
            self.receive_ns = msg.receive_ns
            self.core.advance(msg.receive_ns - self.margin_ns)
        if kind is None:
            return
        what, sid = kind
        if what == "imu":
            self.imu_raw.setdefault(sid, []).append(msg.data)
            self.n_imu += 1
            if self.n_imu >= IMU_BATCH:
                self.flush_imu()
            return
        self._feed_decoded(msg.topic, msg.msgtype, what, sid, msg.data)

    def _feed_decoded(self, topic: str, msgtype: str, what: str, sid: str, data: bytes) -> None:
        try:
            m = self.ts.deserialize_cdr(data, msgtype)
        except Exception as exc:  # one bad message: report and go on
            self.core.report_error(f"{self.path}:{topic}", f"cannot decode {msgtype}: {exc}")
            return
        st = m.header.stamp
        t_ns = int(st.sec) * 1_000_000_000 + int(st.nanosec)
        if what == "block":
            self.flush_imu()
            if m.sample_rate_hz > 0:
                dur = int(len(m.samples) / max(1, len(m.channel_names)) / m.sample_rate_hz * 1e9)
                self.margin_ns = max(self.margin_ns, dur + 1_000_000_000)
            self.core.add_block(t_ns, m.sample_rate_hz, list(m.channel_names), np.asarray(m.samples),
                                m.units, topic=topic.lstrip("/"))
        elif what == "temperature":
            self.core.add_temperature(sid, t_ns, m.temperature)

    def flush_imu(self) -> None:
        if not self.n_imu:
            return
        raw, self.imu_raw, self.n_imu = self.imu_raw, {}, 0
        for sid, datas in raw.items():
            try:
                stamps, xyz = decode_imu_batch(datas)
            except ValueError as exc:
                self.core.report_error(f"{self.path}:accel/{sid}", f"cannot decode Imu messages: {exc}")
                continue
            self.core.add_imu_array(sid, stamps, xyz)


_REC_HEAD = struct.Struct("<BQ")
_MSG_HEAD = struct.Struct("<HIQQ")


def _gather(mv: np.ndarray, starts: np.ndarray, width: int) -> np.ndarray:
    """``(len(starts), width)`` bytes of ``mv`` starting at each of ``starts``."""
    return np.ascontiguousarray(mv[starts[:, None] + np.arange(width)])


def _walk_records(buf: bytes, mv: np.ndarray) -> Iterator[tuple[int, np.ndarray, int]]:
    """``(opcode, record positions, content length)`` of the MCAP records in ``buf``, grouped in
    runs of equal records (a chunk of equal-size messages is one run, found with one numpy check)."""
    pos, n = 0, len(buf)
    unpack_head = _REC_HEAD.unpack_from
    while pos + 9 <= n:
        op, ln = unpack_head(buf, pos)
        size = 9 + ln
        m = (n - pos) // size
        if m > 4:
            P = pos + np.arange(m, dtype=np.int64) * size
            good = (mv[P] == op) & (_gather(mv, P + 1, 8).view("<u8")[:, 0] == ln)
            run = m if good.all() else int(np.argmin(good))
            yield op, P[:run], ln
            pos += run * size
        else:
            yield op, np.asarray([pos], np.int64), ln
            pos += size


class _Damaged(Exception):
    """A fast-path reader met a damaged file after it had fed messages (``__cause__`` says why)."""


def _bag_files(path: Path, storage: str) -> list[Path]:
    """The files of a bag directory of ``storage`` whose messages are not compressed one by one
    (those go through rosbags); [] when that is not what ``path`` is."""
    if not path.is_dir():
        return [path] if storage == "mcap" and path.suffix == ".mcap" else []
    meta = path / "metadata.yaml"
    if not meta.exists():
        return []
    import yaml

    info = (yaml.safe_load(meta.read_text()) or {}).get("rosbag2_bagfile_information", {})
    if info.get("storage_identifier") != storage:
        return []
    if str(info.get("compression_mode") or "").lower() not in ("", "none"):
        if storage == "sqlite3" or str(info.get("compression_mode")).lower() == "message":
            return []
    files = [path / p for p in info.get("relative_file_paths", [])]
    return files if files and all(f.exists() for f in files) else []


def _mcap_files(path: Path) -> list[Path]:
    return _bag_files(path, "mcap")


def _chunk_records(record: bytes) -> bytes:
    """The (decompressed) records inside one MCAP chunk record."""
    op, _ = _REC_HEAD.unpack_from(record, 0)
    if op != 6:
        raise ValueError("not a chunk record")
    pos = 9 + 8 + 8 + 8 + 4
    (clen,) = struct.unpack_from("<I", record, pos)
    compression = record[pos + 4:pos + 4 + clen].decode()
    pos += 4 + clen
    (rlen,) = struct.unpack_from("<Q", record, pos)
    data = record[pos + 8:pos + 8 + rlen]
    if compression == "":
        return data
    if compression == "zstd":
        return _zstd_decompress(data)
    if compression == "lz4":
        import lz4.frame

        return lz4.frame.decompress(data)
    raise ValueError(f"unknown chunk compression {compression!r}")


def _zstd_decompress(data: bytes) -> bytes:
    try:
        from compression import zstd  # Python >= 3.14
    except ImportError:
        try:
            from backports import zstd  # what rosbags uses before 3.14
        except ImportError:
            import zstandard

            return zstandard.ZstdDecompressor().decompress(data, max_output_size=1 << 31)
    return zstd.decompress(data)


def decode_imu_batch(datas: list[bytes]) -> tuple[np.ndarray, np.ndarray]:
    """``(stamps_ns (n,), linear_acceleration (n, 3))`` of CDR-serialised ``sensor_msgs/Imu``.

    Written out with numpy because deserialising message by message (rosbags) costs ~6 us each,
    more than everything else of the offline path together. Little-endian CDR only; anything else
    (or a size that does not fit) goes through the rosbags deserialiser, message by message.
    """
    lengths = np.fromiter((len(d) for d in datas), np.int64, len(datas))
    starts = np.concatenate(([0], np.cumsum(lengths)[:-1])).astype(np.int64)
    mv = np.frombuffer(b"".join(datas), dtype=np.uint8)
    stamps, xyz, ok = _imu_decode(mv, starts, lengths)
    for i in np.flatnonzero(~ok).tolist():
        stamps[i], xyz[i] = _imu_slow(datas[i], i)
    return stamps, xyz


IMU_MIN_LEN = 16 + 200 + 24 + 72


def _imu_decode(mv: np.ndarray, starts: np.ndarray, lengths: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stamps and linear acceleration of the Imu CDR messages at ``mv[starts:starts+lengths]``;
    ``ok`` is False where the fast layout does not apply (those entries are left undefined)."""
    n = starts.size
    stamps = np.zeros(n, np.int64)
    xyz = np.zeros((n, 3), np.float64)
    ok = lengths >= IMU_MIN_LEN
    if not ok.any():
        return stamps, xyz, ok
    r = np.flatnonzero(ok)
    head = _gather(mv, starts[r], 16)
    le = (head[:, 0] == 0) & (head[:, 1] == 1)  # CDR little endian
    words = head[:, 4:16].copy().view("<u4")  # sec, nanosec, frame_id length (with its NUL)
    pos = 16 + words[:, 2].astype(np.int64)
    aligned = 4 + ((pos - 4 + 7) // 8) * 8  # 8-byte alignment counted after the 4-byte header
    off = aligned + 200  # orientation (32) + its covariance (72) + gyro (24) + its covariance (72)
    good = le & (off + 24 + 72 == lengths[r])
    ok[r[~good]] = False
    r, off = r[good], off[good]
    stamps[r] = words[good, 0].astype(np.int32).astype(np.int64) * 1_000_000_000 + words[good, 1]
    xyz[r] = _gather(mv, starts[r] + off, 24).view("<f8")
    return stamps, xyz, ok


def _imu_slow(data: bytes, i: int) -> tuple[int, tuple[float, float, float]]:
    try:
        m = typestore().deserialize_cdr(data, IMU)
    except Exception as exc:
        raise ValueError(f"message {i}: {exc}") from exc
    la = m.linear_acceleration
    return int(m.header.stamp.sec) * 1_000_000_000 + int(m.header.stamp.nanosec), (la.x, la.y, la.z)


def _has(path: Path, suffix: str) -> bool:
    if path.is_dir():
        return any(p.suffix == suffix for p in path.iterdir())
    return path.suffix == suffix


def _is_mcap(path: Path) -> bool:
    return _has(path, ".mcap")


def can_salvage(path: str | Path) -> bool:
    """Whether :func:`salvage` can read this bag's files without the bag's index/metadata."""
    path = Path(path)
    return path.exists() and (_has(path, ".mcap") or _has(path, ".db3"))


def salvage(path: str | Path) -> Iterator[BagMessage]:
    """Messages of a bag whose metadata or index is missing or damaged, read from its storage
    files directly (MCAP record by record, sqlite3 row by row); raises :class:`BagError` naming
    the file where the readable data ends."""
    path = Path(path)
    if _has(path, ".mcap"):
        yield from salvage_mcap(path)
    elif _has(path, ".db3"):
        yield from salvage_sqlite3(path)
    else:
        raise BagError(f"{path}: neither MCAP nor sqlite3 files to read")


_ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"


def salvage_sqlite3(path: str | Path) -> Iterator[BagMessage]:
    """Messages of rosbag2 sqlite3 files read row by row with the ``sqlite3`` module, in the
    order they were written: for a bag whose ``metadata.yaml`` is missing (a recorder that was
    killed) or whose database is damaged part-way. Per-message zstd compression is recognised by
    its magic number. Raises :class:`BagError` naming the file where a damaged one stops."""
    import sqlite3

    path = Path(path)
    files = sorted(path.glob("*.db3")) if path.is_dir() else [path]
    for f in files:
        try:
            con = sqlite3.connect(f"file:{f}?mode=ro&immutable=1", uri=True)
        except sqlite3.Error as exc:
            raise BagError(f"{f}: cannot open sqlite3 bag file ({exc})") from exc
        try:
            topics = {int(i): (str(n), str(t)) for i, n, t in
                      con.execute("SELECT id, name, type FROM topics")}
            for topic_id, stamp, data in con.execute(
                    "SELECT topic_id, timestamp, data FROM messages ORDER BY rowid"):
                topic = topics.get(int(topic_id))
                if topic is None:
                    continue
                raw = bytes(data)
                if raw[:4] == _ZSTD_MAGIC:
                    import zstandard

                    raw = zstandard.ZstdDecompressor().decompress(raw)
                yield BagMessage(topic[0], topic[1], int(stamp), raw)
        except sqlite3.Error as exc:
            raise BagError(f"{f}: damaged sqlite3 bag file ({exc})") from exc
        finally:
            con.close()


def salvage_mcap(path: str | Path) -> Iterator[BagMessage]:
    """Messages of MCAP files read record by record, for files whose summary/footer is missing.

    Yields every message of every complete chunk in file order, then raises :class:`BagError`
    naming the file where the data ends or is damaged.
    """
    path = Path(path)
    try:
        from mcap.records import Channel, Message, Schema
        from mcap.stream_reader import StreamReader
    except ImportError as exc:
        raise BagError(f"{path}: cannot read it record by record without the 'mcap' package") from exc
    files = sorted(path.glob("*.mcap")) if path.is_dir() else [path]
    for f in files:
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, str]] = {}
        try:
            with open(f, "rb") as fh:
                for rec in StreamReader(fh, validate_crcs=True).records:
                    if isinstance(rec, Schema):
                        schemas[rec.id] = rec.name
                    elif isinstance(rec, Channel):
                        channels[rec.id] = (rec.topic, schemas.get(rec.schema_id, ""))
                    elif isinstance(rec, Message):
                        ch = channels.get(rec.channel_id)
                        if ch is not None:
                            yield BagMessage(ch[0], ch[1], int(rec.log_time), bytes(rec.data))
        except Exception as exc:  # EndOfFile, bad CRC, bad record: the data stops here
            raise BagError(f"{f}: damaged or truncated MCAP ({type(exc).__name__} {exc})") from exc


# ----------------------------------------------------------------------------------------------
# windows on disk: one .npz per window (what `shm-ros ingest` writes)


def window_filename(index: int, w: Window) -> str:
    return f"w{index:05d}_{w.window_id.replace(':', '').replace('-', '')}.npz"


def save_window(path: str | Path, w: Window) -> None:
    """One window as ``.npz``: samples, flags (empty = clean), and every other field."""
    np.savez(
        path,
        samples=w.samples,
        flags=w.flags if w.flags is not None else np.zeros((0, 0), np.uint8),
        start_ns=np.int64(w.start_ns),
        sample_rate_hz=np.float64(w.sample_rate_hz),
        channel_names=np.asarray(w.channel_names, dtype=str),
        channel_status=np.asarray(w.channel_status or [], dtype=str),
        temperature_c=np.float64(np.nan if w.temperature_c is None else w.temperature_c),
        is_event=np.bool_(w.is_event),
        pga_m_s2=np.float64(w.pga_m_s2),
        input_channel=np.asarray(w.input_channel or ""),
        window_id=np.asarray(w.window_id),
        notes=np.asarray(w.notes, dtype=str),
    )


def load_window(path: str | Path) -> Window:
    """The :class:`Window` saved by :func:`save_window`."""
    with np.load(path, allow_pickle=False) as z:
        flags = z["flags"]
        t = float(z["temperature_c"])
        return Window(
            window_id=str(z["window_id"]),
            start_ns=int(z["start_ns"]),
            sample_rate_hz=float(z["sample_rate_hz"]),
            channel_names=[str(c) for c in z["channel_names"]],
            samples=np.array(z["samples"]),
            flags=None if flags.size == 0 else np.array(flags),
            channel_status=[str(c) for c in z["channel_status"]] or None,
            temperature_c=None if np.isnan(t) else t,
            is_event=bool(z["is_event"]),
            pga_m_s2=float(z["pga_m_s2"]),
            input_channel=str(z["input_channel"]) or None,
            notes=[str(n) for n in z["notes"]],
        )
