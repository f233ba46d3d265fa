"""What the within-event analysis returns (docs/interfaces.md §3, section ``event``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class StrongMotion:
    """The Arias-intensity interval of the strong shaking, s from the record start."""

    source: str  # "input" | "response"
    channel: str | None  # the input channel, None for the response
    start_s: float
    end_s: float
    arias_low: float
    arias_high: float
    arias_intensity: float  # total; m/s for an acceleration input (pi / 2g integral of a^2)


@dataclass
class ModeTrack:
    """One followed mode through the moving windows (NaN where a window did not find it)."""

    mode: int  # 1-based, lowest reference frequency first
    reference_frequency_hz: float
    reference_damping: float
    frequency_hz: np.ndarray  # (w,)
    damping_ratio: np.ndarray  # (w,)
    frequency_spread_hz: np.ndarray  # (w,) std across model orders of the window's stable poles
    smoothed_frequency_hz: np.ndarray  # (w,) running median (EventConfig.smooth_windows)
    min_index: int | None  # window of the smoothed minimum

    def minimum(self, time_s: np.ndarray, amplitude: np.ndarray) -> dict[str, float] | None:
        if self.min_index is None:
            return None
        k = self.min_index
        f = float(self.smoothed_frequency_hz[k])
        return {"frequency_hz": f, "time_s": float(time_s[k]), "response_rms_m_s2": float(amplitude[k]),
                "drop": 1.0 - f / self.reference_frequency_hz}


@dataclass
class PhaseMode:
    mode: int
    frequency_hz: float
    damping_ratio: float
    frequency_std_hz: float  # from the spread over sub-windows (EventResult doc)
    damping_std: float
    n_sub_windows: int  # sub-windows that found the mode


@dataclass
class PhaseEstimate:
    """One estimate of a whole phase (pre-event, strong motion or post-event)."""

    name: str
    start_s: float
    end_s: float
    modes: list[PhaseMode] = field(default_factory=list)
    sub_window_s: float = 0.0
    note: str | None = None


@dataclass
class EventResult:
    """Frequency and damping of the followed modes against time and response amplitude.

    ``window_start_s``: moving windows ``[start, start + window_s)`` (s from the record start), the
    track values sit at ``time_s`` (their centres). ``response_rms_m_s2``: RMS over each window of
    ``amplitude_channel`` (the output with the largest RMS over the record, after pre-processing);
    ``input_rms_m_s2`` / ``input_peak_m_s2`` the same for the input channel (NaN without one).
    Phase standard deviations: std of the estimates of half-overlapping sub-windows of the phase times
    ``sqrt(sub-window / phase length)`` (estimation variance taken inversely proportional to the data
    length); inside the strong motion this also holds the mode's real movement.
    """

    window_id: str
    start_ns: int
    method: str
    input_channel: str | None
    sample_rate_hz: float  # after decimation
    lowest_frequency_hz: float
    window_s: float
    step_s: float
    max_order: int
    block_rows: int
    window_start_s: np.ndarray
    response_rms_m_s2: np.ndarray
    input_rms_m_s2: np.ndarray
    input_peak_m_s2: np.ndarray
    amplitude_channel: str
    strong_motion: StrongMotion
    tracks: list[ModeTrack]
    phases: list[PhaseEstimate]
    input_time_s: np.ndarray  # the (decimated) input record for plots; empty without an input
    input_m_s2: np.ndarray
    notes: list[str] = field(default_factory=list)

    @property
    def time_s(self) -> np.ndarray:
        return self.window_start_s + 0.5 * self.window_s

    def phase(self, name: str) -> PhaseEstimate | None:
        return next((p for p in self.phases if p.name == name), None)

    def to_record(self) -> dict[str, Any]:
        """The JSON record of docs/interfaces.md §3 (``event``); NaN becomes null."""
        t, amp = self.time_s, self.response_rms_m_s2
        sm = self.strong_motion
        return {
            "window_id": self.window_id,
            "method": self.method,
            "input_sensor": self.input_channel,
            "lowest_frequency_hz": _num(self.lowest_frequency_hz),
            "moving_window": {"length_s": self.window_s, "step_s": self.step_s, "max_order": self.max_order,
                              "block_rows": self.block_rows, "sample_rate_hz": self.sample_rate_hz},
            "strong_motion": {"source": sm.source, "channel": sm.channel, "start_s": sm.start_s, "end_s": sm.end_s,
                              "arias_fractions": [sm.arias_low, sm.arias_high],
                              "arias_intensity": _num(sm.arias_intensity)},
            "amplitude_channel": self.amplitude_channel,
            "windows": {"time_s": _list(t), "response_rms_m_s2": _list(amp),
                        "input_rms_m_s2": _list(self.input_rms_m_s2), "input_peak_m_s2": _list(self.input_peak_m_s2)},
            "modes": [{"mode": m.mode, "reference_frequency_hz": _num(m.reference_frequency_hz),
                       "reference_damping": _num(m.reference_damping),
                       "frequency_hz": _list(m.frequency_hz), "damping_ratio": _list(m.damping_ratio),
                       "frequency_spread_hz": _list(m.frequency_spread_hz),
                       "minimum": m.minimum(t, amp)} for m in self.tracks],
            "phases": {p.name: {"start_s": p.start_s, "end_s": p.end_s, "sub_window_s": p.sub_window_s,
                                "note": p.note,
                                "modes": [{"mode": m.mode, "frequency_hz": _num(m.frequency_hz),
                                           "damping_ratio": _num(m.damping_ratio),
                                           "frequency_std_hz": _num(m.frequency_std_hz),
                                           "damping_std": _num(m.damping_std), "n_sub_windows": m.n_sub_windows}
                                          for m in p.modes]} for p in self.phases},
            "notes": list(self.notes),
        }


def _num(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(float(x)) else float(x)


def _list(a: np.ndarray) -> list[float | None]:
    return [_num(v) for v in np.asarray(a, dtype=float)]
