"""Diagnostic levels and records, shared by the cores and every node.

:class:`Level` has the values of ``diagnostic_msgs/DiagnosticStatus`` (OK 0, WARN 1, ERROR 2,
STALE 3), so a node publishes ``int(level)`` as it is; the cores never import ROS.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any

from shm_ros.core.timeutil import ns_to_iso


class Level(enum.IntEnum):
    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3  # no news (diagnostic_msgs); the cores never report it, the nodes may

    @property
    def label(self) -> str:
        """The word written in JSON outputs and log lines."""
        return _LABELS[self]

    @classmethod
    def parse(cls, value: Level | int | str) -> Level:
        """A level from itself, its number, its label or its name (``"warn"``, ``"warning"``)."""
        if isinstance(value, str):
            key = value.strip().lower()
            for level in cls:
                if key in (level.name.lower(), level.label):
                    return level
            raise ValueError(f"unknown diagnostic level {value!r}")
        return cls(int(value))


_LABELS = {Level.OK: "info", Level.WARN: "warning", Level.ERROR: "error", Level.STALE: "stale"}


@dataclass
class Diagnostic:
    """One reported fault or event."""

    level: Level
    code: str
    source: str  # what it is about, e.g. "accel/s1.linear_acceleration.z" or "accel_block.samples[s3]"
    message: str
    stamp_ns: int | None = None  # data time it refers to (None: not tied to a time)
    count: int = 1  # occurrences this record stands for

    def __post_init__(self) -> None:
        self.level = Level.parse(self.level)

    def __str__(self) -> str:
        when = f" at {ns_to_iso(self.stamp_ns)}" if self.stamp_ns is not None else ""
        return f"[{self.level.label}] {self.code} {self.source}{when}: {self.message}"

    def to_dict(self) -> dict[str, Any]:
        return {"level": self.level.label, "code": self.code, "source": self.source, "message": self.message,
                "time": None if self.stamp_ns is None else ns_to_iso(self.stamp_ns), "count": self.count}
