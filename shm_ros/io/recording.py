"""A recorded bag -> the streaming ingest core -> windows (the offline path of ``ingest``).

The same :class:`~shm_ros.core.ingest.IngestCore` runs here and in the live node: this module only
feeds it. The bag is read by the back end :func:`~shm_ros.io.sources.open_source` picks for it,
in batches; each batch's Imu messages of a topic are decoded together from their CDR bytes
(:mod:`shm_ros.io.imu_cdr`), which is what makes per-sample Imu bags fast to ingest.

A damaged bag never raises: every window that the data read before the damage makes is kept and the
error, naming the file, is reported as a diagnostic. Nothing is read twice: a bag is read by one
back end from start to end, and any other error propagates (it is a bug, not damage).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.core.ingest import (
    ChannelMap,
    Diagnostic,
    DroppedSpan,
    IngestConfig,
    IngestCore,
    IngestStats,
    Level,
    channel_mismatches,
)
from shm_ros.core.types import Window
from shm_ros.io.bags import BagError, topic_kind
from shm_ros.io.imu_cdr import decode_imu_views
from shm_ros.io.sources import Batch, TopicMessages, open_source
from shm_ros.io.typestore import typestore


@dataclass
class IngestResult:
    windows: list[Window]
    diagnostics: list[Diagnostic]
    stats: IngestStats
    dropped: list[DroppedSpan]
    sample_rate_hz: float | None  # the first burst's; every window carries its own burst's rate
    ignored_topics: list[str] = field(default_factory=list)
    messages: int = 0
    diagnostic_counts: dict = field(default_factory=dict)  # (code, source) -> occurrences
    # structure sensors that no topic feeds and accelerometer topics/channels that feed no sensor,
    # with the closest names (also among ``diagnostics``): for the terminal, up front
    mismatches: list[Diagnostic] = field(default_factory=list)
    sample_rates_hz: list[float] = field(default_factory=list)  # distinct burst rates, first seen first


def channel_map_of(structure_or_map: Any) -> ChannelMap:
    """A :class:`ChannelMap` from a map, a ``StructureSpec`` or the path of a structure file."""
    if isinstance(structure_or_map, ChannelMap):
        return structure_or_map
    if isinstance(structure_or_map, (str, Path)):
        from shm_ros.io.structure import load_structure

        return ChannelMap.from_structure(load_structure(structure_or_map))
    return ChannelMap.from_structure(structure_or_map)


def windows_from_bag(path: str | Path, structure_or_channel_map: Any, window_s: float | None = None, *,
                     config: IngestConfig | None = None) -> tuple[list[Window], list[Diagnostic]]:
    """All windows of a bag and the diagnostics found on the way (see :func:`ingest_bag`)."""
    res = ingest_bag(path, structure_or_channel_map, window_s, config=config)
    return res.windows, res.diagnostics


def ingest_bag(path: str | Path, structure_or_channel_map: Any, window_s: float | None = None, *,
               config: IngestConfig | None = None, margin_s: float = 10.0) -> IngestResult:
    """Read a bag through :class:`IngestCore`; unrelated topics are ignored (and listed).

    ``config`` overrides every setting except ``window_s`` when given (its ``window_s`` is replaced
    by the argument; None: the configuration's, by default the ingest default of 600 s, so that an
    event shorter than it is one window of its own length). Messages come in receive-time order; a
    window is cut once the receive time is
    ``margin_s`` past its end (so header stamps may lag receive times by up to ``margin_s``; an
    AccelBlock longer than that widens the margin).
    """
    cmap = channel_map_of(structure_or_channel_map)
    base = IngestConfig() if config is None else config
    config = IngestConfig(**{**base.__dict__, "window_s": base.window_s if window_s is None else window_s,
                             "max_latency_s": float("inf")})
    core = IngestCore(cmap, config)
    feeder = _BagFeeder(core, Path(path), margin_s)
    feeder.run()
    windows = core.flush()
    return IngestResult(windows, core.diagnostics, core.stats, core.dropped, core.sample_rate_hz,
                        sorted(feeder.ignored), feeder.n_messages, dict(core.diagnostic_counts),
                        feeder.mismatches, core.sample_rates_hz)


class _BagFeeder:
    """Feeds the core the messages of one bag, batch by batch, in receive order."""

    def __init__(self, core: IngestCore, path: Path, margin_s: float) -> None:
        self.core = core
        self.path = path
        self.margin_ns = int(margin_s * 1e9)
        self.ignored: set[str] = set()
        self.kinds: dict[str, tuple[str, str] | None] = {}
        self.n_messages = 0
        self.ts = typestore()
        self.mismatches: list[Diagnostic] = []
        self._block_channels: set[str] = set()
        self._channels_checked = False

    def run(self) -> None:
        source = str(self.path)
        try:
            bag = open_source(self.path)
        except BagError as exc:  # nothing to read (no such bag, no storage files)
            self.core.report_error(source, str(exc), code="bag_damaged")
            return
        if bag.note:
            self.core.report_error(source, bag.note, level=Level.WARN, code="bag_damaged")
        try:
            kinds = {t: topic_kind(t, ty) for t, ty in bag.topics().items()}
        except BagError:  # the topic list itself is damaged: reading the messages will say how
            kinds, self._channels_checked = {}, True
        accel = sorted(t for t, k in kinds.items() if k and k[0] == "imu")
        temps = sorted(t for t, k in kinds.items() if k and k[0] == "temperature")
        has_blocks = any(k and k[0] == "block" for k in kinds.values())
        # up front; with DAQ blocks, once the first blocks have named their channels
        if not has_blocks and not self._channels_checked:
            self._check_channels(accel, temps)
        try:
            for batch in bag.batches():
                self.feed(batch)
                if not self._channels_checked:
                    self._check_channels(accel, temps)
        except BagError as exc:  # the back end met the end of the readable data
            self.core.report_error(source, f"{exc} ({self.n_messages} messages read before the damage "
                                   "were ingested)", code="bag_damaged")
        if self.ignored:
            self.core.report_error(source, "ignored topics (not accelerometer/temperature "
                                   "recording topics): " + ", ".join(sorted(self.ignored)),
                                   level=Level.OK, code="ignored_topics")

    def feed(self, batch: Batch) -> None:
        for run in batch.runs:
            self.n_messages += len(run)
            kind = self._kind(run.topic, run.msgtype)
            if kind is None:
                continue
            what, sid = kind
            if what == "imu":
                self._feed_imu(sid, run)
            elif what == "block":
                self._feed_blocks(run)
            else:
                for i in range(len(run)):
                    self._feed_decoded(run.topic, run.msgtype, what, sid, run.data(i))
        if batch.complete_before_ns is not None:
            self.core.advance(batch.complete_before_ns - self.margin_ns)

    def _check_channels(self, accel: list[str], temps: list[str]) -> None:
        self._channels_checked = True
        self.mismatches = channel_mismatches(self.core.map, accel, temps, sorted(self._block_channels))
        for d in self.mismatches:
            self.core.report_error(d.source, d.message, level=d.level, code=d.code)

    def _kind(self, topic: str, msgtype: str) -> tuple[str, str] | None:
        if topic not in self.kinds:
            kind = self.kinds[topic] = topic_kind(topic, msgtype)
            if kind is None:
                self.ignored.add(f"{topic} ({msgtype})")
        return self.kinds[topic]

    def _feed_imu(self, sid: str, run: TopicMessages) -> None:
        out = decode_imu_views(run.buf, run.starts, run.lengths)
        for i, why in out.failures:  # one bad message: report it, keep the others
            self.core.report_error(f"{self.path}:{run.topic}", f"cannot decode Imu message "
                                   f"received at {int(run.log_ns[i])} ns: {why}")
        self.core.add_accel(sid, out.stamps_ns, out.xyz, field="linear_acceleration")

    def _decode(self, topic: str, msgtype: str, data: bytes) -> tuple[Any, int] | None:
        """A message and its header stamp (ns); None (reported) when it cannot be decoded."""
        from rosbags.serde import SerdeError

        try:
            m: Any = self.ts.deserialize_cdr(data, msgtype)
        except SerdeError as exc:  # one malformed message (rosbags wraps every parse error): go on
            self.core.report_error(f"{self.path}:{topic}", f"cannot decode {msgtype}: {exc}")
            return None
        st = m.header.stamp
        return m, int(st.sec) * 1_000_000_000 + int(st.nanosec)

    def _feed_blocks(self, run: TopicMessages) -> None:
        """A run of AccelBlocks: consecutive blocks with one rate, channel list and units go to the
        core together (:meth:`IngestCore.add_blocks`)."""
        topic = run.topic.lstrip("/")
        key: tuple | None = None
        stamps: list[int] = []
        samples: list[np.ndarray] = []
        for i in range(len(run)):
            got = self._decode(run.topic, run.msgtype, run.data(i))
            if got is None:
                continue
            m, t_ns = got
            if m.sample_rate_hz > 0:
                dur = int(len(m.samples) / max(1, len(m.channel_names)) / m.sample_rate_hz * 1e9)
                self.margin_ns = max(self.margin_ns, dur + 1_000_000_000)
            self._block_channels.update(m.channel_names)
            k = (m.sample_rate_hz, tuple(m.channel_names), m.units)
            if k != key and stamps:
                assert key is not None
                self.core.add_blocks(stamps, key[0], key[1], samples, key[2], topic=topic)
                stamps, samples = [], []
            key = k
            stamps.append(t_ns)
            samples.append(np.asarray(m.samples))
        if stamps:
            assert key is not None
            self.core.add_blocks(stamps, key[0], key[1], samples, key[2], topic=topic)

    def _feed_decoded(self, topic: str, msgtype: str, what: str, sid: str, data: bytes) -> None:
        got = self._decode(topic, msgtype, data)
        if got is None:
            return
        m, t_ns = got
        if what == "temperature":
            self.core.add_temperature(sid, t_ns, m.temperature)
