"""Nanosecond time stamps: the one place that converts them to and from seconds + nanoseconds and
ISO 8601 text.

The pipeline keeps time as integer nanoseconds since the Unix epoch (UTC) everywhere; float64
seconds cannot hold an epoch time to the nanosecond, so every conversion here is integer
arithmetic. Message stamps (``sec``, ``nanosec``) are split and joined with :func:`split_ns` and
:func:`join_ns`; the adapters read the message fields themselves.
"""

from __future__ import annotations

from datetime import datetime, timezone

NS_PER_S = 1_000_000_000


def split_ns(t_ns: int) -> tuple[int, int]:
    """``(sec, nanosec)`` with ``0 <= nanosec < 1e9`` (also for times before the epoch)."""
    sec, nsec = divmod(int(t_ns), NS_PER_S)
    return sec, nsec


def join_ns(sec: int, nanosec: int) -> int:
    """Nanoseconds since the epoch from a stamp's ``sec`` and ``nanosec``."""
    return int(sec) * NS_PER_S + int(nanosec)


def ns_to_iso(t_ns: int) -> str:
    """``2024-05-01T00:00:00.005Z``: UTC, millisecond resolution (truncated, not rounded, so that
    a window id never names a later millisecond than its first sample)."""
    sec, nsec = split_ns(t_ns)
    dt = datetime.fromtimestamp(sec, tz=timezone.utc)
    return dt.strftime("%Y-%m-%dT%H:%M:%S") + f".{nsec // 1_000_000:03d}Z"


def iso_to_ns(text: str) -> int:
    """ISO 8601 (``...Z``, an offset, or naive = UTC) -> nanoseconds since the epoch, exact to the
    microsecond (what ``datetime`` holds). Raises ``ValueError`` for text that is not ISO 8601."""
    dt = datetime.fromisoformat(text.strip().replace("Z", "+00:00"))
    if dt.tzinfo is None:
        dt = dt.replace(tzinfo=timezone.utc)
    whole = int(dt.replace(microsecond=0).timestamp())
    return whole * NS_PER_S + dt.microsecond * 1000
