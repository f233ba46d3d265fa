"""Settings of the ingest core, one :func:`~shm_ros.core.config.option` per field.

The node's parameters and the ``shm-ros ingest`` flags take their defaults and help from here.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from shm_ros.core.config import check_choice, option


class EventDetector(enum.StrEnum):
    """Which trigger makes a window an event."""

    STA_LTA = "sta_lta"
    PGA = "pga"
    EITHER = "either"
    BOTH = "both"
    NONE = "none"


MIN_WINDOW_S = 1.0  # a shorter window holds less than a period of most structures' modes


@dataclass
class IngestConfig:
    """Settings of :class:`~shm_ros.core.ingest.core.IngestCore`."""

    window_s: float = option(600.0, "window length, s; long bursts are split into windows of this length")
    min_window_s: float = option(
        20.0, "a burst shorter than window_s is one window of its own length when at least this long "
        "(or half a window, if that is shorter), s")
    sample_rate_hz: float | None = option(
        None, "grid sample rate of every burst, Hz (default: per burst, its AccelBlocks' rate or fitted to "
        "its Imu stamps)")
    burst_pause_s: float = option(1.0, "a pause longer than this (no channel has data) ends a burst, s")
    snap_tolerance: float = option(
        0.5, "a stamp snaps to a grid point strictly closer than this fraction of a period")
    max_latency_s: float = option(
        120.0, "streaming: a window waits at most this long (stamp time, median channel past its end) "
        "for a lagging or silent channel, s; with settle_s this only bounds that wait, so it is long "
        "(a replay delivers minutes of stamp time quickly); inf = everything waits for the end of "
        "the stream (offline readers that know their order call advance() themselves)", cli=False)
    settle_s: float | None = option(
        2.0, "streaming: a window is cut as soon as EVERY channel's newest stamp is this far past "
        "its end, s (DDS keeps each topic in order, not across topics; 2 s covers the spread of "
        "topics in a live graph); None: only max_latency_s decides", cli=False)
    min_coverage: float = option(0.5, "a channel with less than this fraction of a window's samples is dropped for it")
    clip_run: int = option(3, "this many equal samples at a channel's extreme count as clipping")
    saturation_m_s2: float | None = option(None, "|a| at or above this is flagged CLIPPED (default: only flat tops)")
    dead_ptp_m_s2: float = option(0.0, "a channel whose peak-to-peak in a window is at most this is dead")
    spike_k: float = option(12.0, "an isolated sample this many robust sigmas from its 5-point median is a spike")
    noisy_fraction: float = option(0.01, "a channel with more NaN/spike samples than this fraction is 'noisy'")
    event_detector: str = option(EventDetector.STA_LTA.value, "earthquake/event trigger", choices=EventDetector)
    sta_s: float = option(1.0, "STA window, s")
    lta_s: float = option(30.0, "LTA window, s")
    sta_lta_on: float = option(
        10.0, "STA/LTA ratio that triggers an event (narrow-band ambient response of a lightly damped "
        "structure reaches 5-9 within 10 min; earthquakes go far above 10)")
    pga_threshold_m_s2: float = option(0.5, "peak |a - median| that triggers an event (pga, either, both)")
    earthquake_pga_m_s2: float = option(
        0.05, "a triggered window is an earthquake when its ground/input channel has at least this PGA and its "
        "own STA/LTA fires; other triggered windows are high-amplitude windows (traffic, wind, works)")
    check_interval_s: float = option(5.0, "streaming: at most this often (stamp time) a burst end is looked for, s",
                                     cli=False)
    rate_tolerance: float = option(0.01, "relative difference of a channel's rate from the grid's that is reported")
    implausible_m_s2: float = option(
        196.133, "|a| above this (20 g = 196.133 m/s^2) is implausible for a structure: the sample becomes NaN and is "
        "reported")
    clock_jump_s: float = option(86400.0, "stamps that step forward by more than this, s (or back at all) "
                                 "are reported as a clock jump")
    max_repeats: int = option(5, "diagnostics of one code and source recorded between two windows (the rest counted)")

    def __post_init__(self) -> None:
        if not MIN_WINDOW_S <= self.window_s < math.inf:
            raise ValueError(f"window_s must be at least {MIN_WINDOW_S:g} s and finite, got {self.window_s}")
        if not self.implausible_m_s2 > 0:
            raise ValueError(f"implausible_m_s2 must be > 0, got {self.implausible_m_s2}")
        if not self.clock_jump_s > 0:
            raise ValueError(f"clock_jump_s must be > 0, got {self.clock_jump_s}")
        if not self.min_window_s >= 0:
            raise ValueError(f"min_window_s must be >= 0, got {self.min_window_s}")
        if not 0 < self.snap_tolerance <= 0.5:
            raise ValueError(f"snap_tolerance must be in (0, 0.5], got {self.snap_tolerance}")
        check_choice("ingest", "event_detector", self.event_detector, EventDetector)
        self.event_detector = EventDetector(self.event_detector)
        if self.sample_rate_hz is not None and not 0.1 <= self.sample_rate_hz <= 100_000.0:
            raise ValueError(f"sample_rate_hz must be in [0.1, 100000], got {self.sample_rate_hz}")
        if self.settle_s is not None and not self.settle_s >= 0:
            raise ValueError(f"settle_s must be >= 0, got {self.settle_s}")
        if not self.max_latency_s >= 0:
            raise ValueError(f"max_latency_s must be >= 0 (inf: wait for the end), got {self.max_latency_s}")

    @property
    def streaming(self) -> bool:
        """Windows are cut while data comes in (False: everything waits for the end of the stream)."""
        return math.isfinite(self.max_latency_s)
