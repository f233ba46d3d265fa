"""What the ingest core hands back besides windows: dropped stretches, counters, a plain summary."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from shm_ros.core.timeutil import ns_to_iso
from shm_ros.core.types import SampleFlag, Window


@dataclass
class DroppedSpan:
    """A stretch of aligned data that went into no window, and why."""

    start_ns: int
    end_ns: int
    n_samples: int  # grid rows
    reason: str


@dataclass
class IngestStats:
    """Channel-sample accounting: ``samples_in == samples_windowed + sum(samples_not_windowed)``
    once the stream is flushed (a sample of a dropped channel that is absent counts nowhere)."""

    samples_in: int = 0  # well-formed channel samples handed to the core (late ones included)
    samples_windowed: int = 0  # channel samples placed in emitted windows
    samples_not_windowed: Counter[str] = field(default_factory=Counter)  # reason -> channel samples
    messages_rejected: int = 0
    windows: int = 0
    implausible: int = 0  # samples beyond implausible_m_s2, set to NaN


def windows_summary(windows: Iterable[Window]) -> list[dict[str, Any]]:
    """One plain record per window (for JSON outputs and the CLI)."""
    out = []
    for w in windows:
        flags = w.flags
        out.append({
            "window_id": w.window_id,
            "start": ns_to_iso(w.start_ns),
            "end": ns_to_iso(w.end_ns),
            "start_ns": int(w.start_ns),
            "end_ns": int(w.end_ns),
            "sample_rate_hz": w.sample_rate_hz,
            "n_samples": w.n_samples,
            "channel_names": list(w.channel_names),
            "channel_status": list(w.channel_status or []),
            "temperature_c": w.temperature_c,
            "is_event": bool(w.is_event),
            "event_kind": w.event_kind or ("high_amplitude" if w.is_event else "none"),
            "pga_m_s2": float(w.pga_m_s2),
            "input_channel": w.input_channel,
            "covariates": dict(w.covariates),
            "flagged_samples": {} if flags is None else {
                name: {f.name.lower(): int(((flags[:, c] & f) != 0).sum())
                       for f in SampleFlag if f and f.name and ((flags[:, c] & f) != 0).any()}
                for c, name in enumerate(w.channel_names)
            },
            "notes": list(w.notes),
        })
    return out
