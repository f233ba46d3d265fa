"""Settings of the within-event analysis; every default is derived from the lowest frequency of
interest, so an event is analysed without tuning."""

from __future__ import annotations

import enum
from dataclasses import asdict, dataclass

from shm_ros.core.config import check_choice, option
from shm_ros.core.identify import Method


class IntensitySource(enum.StrEnum):
    """Which record's Arias intensity bounds the strong motion."""

    AUTO = "auto"  # the input channel when the window has one, else the response
    INPUT = "input"
    RESPONSE = "response"  # sum of the squared output accelerations


@dataclass
class EventConfig:
    method: str = option(Method.AUTO.value, "identification method of every window: auto (input-output "
                         "SSI when the window has a usable input channel, else covariance-driven)",
                         choices=Method)
    lowest_frequency_hz: float | None = option(None, "lowest frequency of interest, Hz (unset: the "
                                               "structure's first natural frequency, else the record's "
                                               "lowest identified mode)")
    n_periods: float = option(10.0, "moving-window length in periods of the lowest frequency")
    window_s: float | None = option(None, "moving-window length, s (unset: n_periods / lowest frequency)")
    step_s: float | None = option(None, "moving-window step, s (unset: a tenth of the window)")
    target_rate_hz: float | None = option(None, "decimate to about this rate, Hz (unset: 20 x the "
                                          "lowest frequency)")
    max_order: int = option(20, "largest model order of a moving window")
    block_rows: int | None = option(None, "block rows of a moving window (unset: max(ceil(max_order / "
                                    "outputs) + 2, half a period of the lowest frequency))")
    phase_max_order: int = option(40, "largest model order of the pre-event / strong-motion / "
                                  "post-event estimates")
    n_modes: int = option(3, "modes followed through the event, lowest first")
    max_drop: float = option(0.5, "a followed mode may fall to (1 - max_drop) of its reference frequency")
    mac_min: float = option(0.8, "a window's mode matches a followed mode with at least this MAC")
    arias_low: float = option(0.05, "strong motion starts at this fraction of the Arias intensity")
    arias_high: float = option(0.95, "strong motion ends at this fraction of the Arias intensity")
    intensity_source: str = option(IntensitySource.AUTO.value, "record whose Arias intensity bounds the "
                                   "strong motion: auto (the input when input-output SSI runs), input or response",
                                   choices=IntensitySource)
    recovery_ratio: float = option(2.0, "the post-event phase starts once the moving-window response RMS "
                                   "is back below this multiple of the pre-event median (without a "
                                   "pre-event phase: below 1/20 of the largest window's)")
    # A running median over 3 windows raised the minimum by up to 3 % and moved it by up to 5 s on the
    # simulated softening building (the dip of the strongest cycles lasts about one window step),
    # while the raw minimum stayed within 2.3 % and one step: hence no smoothing by default.
    smooth_windows: int = option(1, "the reported minimum is that of a running median over this many "
                                 "windows (1: the raw track)")
    sub_windows: int = option(6, "half-overlapping sub-windows of a phase whose spread gives the "
                              "phase estimate's standard deviation (fewer when a phase is short)")

    def to_dict(self) -> dict:
        return asdict(self)

    def validate(self) -> EventConfig:
        """Raise ``ValueError`` naming the option when a value is out of range."""
        check_choice("event", "method", self.method, Method)
        check_choice("event", "intensity_source", self.intensity_source, IntensitySource)
        if not 0.0 <= self.arias_low < self.arias_high <= 1.0:
            raise ValueError(f"event: need 0 <= arias_low < arias_high <= 1, got {self.arias_low}, "
                             f"{self.arias_high}")
        if not 0.0 < self.max_drop < 1.0:
            raise ValueError(f"event.max_drop: {self.max_drop} is not in (0, 1)")
        for name in ("recovery_ratio", "n_periods", "window_s", "step_s", "target_rate_hz", "lowest_frequency_hz"):
            v = getattr(self, name)
            if v is not None and v <= 0:
                raise ValueError(f"event.{name}: must be positive, got {v}")
        if self.n_modes < 1 or self.max_order < 2 or self.smooth_windows < 1 or self.sub_windows < 3:
            raise ValueError("event: n_modes >= 1, max_order >= 2, smooth_windows >= 1 and sub_windows >= 3")
        return self
