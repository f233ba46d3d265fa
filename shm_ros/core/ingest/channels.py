"""Which input feeds which output channel, and what does not fit together.

An output channel is a sensor of the structure file (a window column). It reads one axis of an
accelerometer topic ``.../accel/<id>`` (given to the core as the id and three axis arrays) and/or
one channel of an AccelBlock (by name). :func:`channel_mismatches` compares the map with the
topics and block channels a bag or a graph actually has, before any data is read, and names the
closest spellings.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from shm_ros.core.diagnostics import Diagnostic, Level

AXES = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True)
class ChannelSource:
    """Where one output channel (a sensor of the structure file) reads its samples.

    ``imu_topic``: last element of the ``.../accel/<id>`` topic (None: not from an accelerometer
    topic); ``axis``: x | y | z of its acceleration; ``block_channel``: AccelBlock channel name
    (None: not from an AccelBlock); ``sign`` multiplies the samples.
    """

    sensor_id: str
    imu_topic: str | None
    axis: str = "z"
    block_channel: str | None = None
    sign: float = 1.0

    def describe(self) -> str:
        """``accel/<id> axis z | accel_block channel <name>`` (for messages)."""
        out = []
        if self.imu_topic is not None:
            out.append(f"accel/{self.imu_topic} axis {self.axis}")
        if self.block_channel is not None:
            out.append(f"accel_block channel {self.block_channel}")
        return " | ".join(out)


@dataclass
class ChannelMap:
    """Output channels (window columns, in order) and where each reads its samples."""

    sources: list[ChannelSource]
    input_sensor: str | None = None

    def __post_init__(self) -> None:
        ids = [s.sensor_id for s in self.sources]
        if len(set(ids)) != len(ids):
            raise ValueError(f"channel map: duplicate sensor ids in {ids}")
        for s in self.sources:
            if s.axis not in AXES:
                raise ValueError(f"channel map: sensor {s.sensor_id!r}: unknown axis {s.axis!r}")
            if s.imu_topic is None and s.block_channel is None:
                raise ValueError(f"channel map: sensor {s.sensor_id!r} reads from nothing")

    @property
    def sensor_ids(self) -> list[str]:
        return [s.sensor_id for s in self.sources]

    @classmethod
    def simple(cls, sensor_axes: dict[str, str] | Sequence[str], input_sensor: str | None = None
               ) -> ChannelMap:
        """Each sensor from the accelerometer topic of its id (given axis, default z) or the block
        channel of its id."""
        if not isinstance(sensor_axes, dict):
            sensor_axes = {s: "z" for s in sensor_axes}
        return cls([ChannelSource(s, s, a, s) for s, a in sensor_axes.items()], input_sensor)

    @classmethod
    def from_structure(cls, spec: Any) -> ChannelMap:
        """From a :class:`shm_ros.core.structure.StructureSpec` (sources already resolved)."""
        out = []
        for s in spec.sensors:
            src = s.source
            out.append(ChannelSource(s.id, src.topic, src.axis, src.channel, float(src.sign)))
        return cls(out, getattr(spec, "input_sensor", None))

    def imu_routes(self) -> dict[str, list[tuple[int, int, float]]]:
        """Topic id -> ``(column, axis index, sign)`` of every channel it feeds."""
        out: dict[str, list[tuple[int, int, float]]] = {}
        for col, s in enumerate(self.sources):
            if s.imu_topic is not None:
                out.setdefault(s.imu_topic, []).append((col, AXES[s.axis], float(s.sign)))
        return out

    def block_routes(self) -> dict[str, list[tuple[int, float]]]:
        """Block channel name -> ``(column, sign)`` of every channel it feeds."""
        out: dict[str, list[tuple[int, float]]] = {}
        for col, s in enumerate(self.sources):
            if s.block_channel is not None:
                out.setdefault(s.block_channel, []).append((col, float(s.sign)))
        return out


def topic_id(topic: str) -> str:
    """The last element of a topic name (``/shm/accel/s1`` -> ``s1``); a bare id stays as it is."""
    return topic.rstrip("/").rsplit("/", 1)[-1]


def _closest(name: str, candidates: Iterable[str]) -> list[str]:
    return difflib.get_close_matches(name, sorted(set(candidates)), n=3, cutoff=0.6)


def _hint(close: list[str], what: str) -> str:
    return f"; closest {what}: {', '.join(close)}" if close else f"; no {what} with a similar name"


def channel_mismatches(channel_map: ChannelMap, accel_topics: Iterable[str],
                       temperature_topics: Iterable[str] = (), block_channels: Iterable[str] = ()
                       ) -> list[Diagnostic]:
    """Warnings for what does not fit between the structure's sensors and the inputs present.

    ``accel_topics``: the accelerometer topics of a bag or a graph (full names such as
    ``/shm/accel/s1``, or bare ids); ``temperature_topics``: its temperature topics (only used to
    explain a sensor that has one but no accelerometer topic); ``block_channels``: the AccelBlock
    channel names seen. Returns one ``sensor_unmatched`` warning per structure sensor that no input
    feeds, one ``unknown_topic`` warning per accelerometer topic and one ``unknown_channel`` per
    block channel that feeds no sensor, each naming the closest names on the other side (``difflib.get_close_matches``).
    """
    topics = {topic_id(t): t for t in accel_topics}
    temps = {topic_id(t) for t in temperature_topics}
    blocks = set(block_channels)
    imu_routes = channel_map.imu_routes()
    out: list[Diagnostic] = []
    for s in channel_map.sources:
        if (s.imu_topic is not None and s.imu_topic in topics) or (
                s.block_channel is not None and s.block_channel in blocks):
            continue
        wanted = s.imu_topic if s.imu_topic is not None else s.block_channel
        assert wanted is not None  # ChannelMap checks that every sensor reads from something
        close = [topics[c] for c in _closest(wanted, topics)] + [
            f"accel_block channel {c}" for c in _closest(wanted, blocks)]
        extra = " (it has a temperature topic only)" if s.sensor_id in temps else ""
        out.append(Diagnostic(
            Level.WARN, "sensor_unmatched", f"sensor {s.sensor_id}",
            f"structure sensor {s.sensor_id} reads {s.describe()}, which no input carries{extra}: "
            f"its channel will be empty{_hint(close, 'inputs')}"))
    for tid, topic in sorted(topics.items()):
        if tid in imu_routes:
            continue
        close = _closest(tid, list(imu_routes) + channel_map.sensor_ids)
        out.append(Diagnostic(
            Level.WARN, "unknown_topic", topic,
            f"accelerometer topic {topic} feeds no structure sensor: ignored"
            f"{_hint(close, 'sensor topics')}"))
    block_routes = channel_map.block_routes()
    for name in sorted(blocks - set(block_routes)):
        close = _closest(name, list(block_routes) + channel_map.sensor_ids)
        out.append(Diagnostic(
            Level.WARN, "unknown_channel", f"accel_block channel {name}",
            f"AccelBlock channel {name} feeds no structure sensor: ignored{_hint(close, 'sensor channels')}"))
    return out
