"""The data that flows between stages, defined once.

recordings -> :class:`Window` -> :class:`ModalEstimate` -> tracked table -> posterior -> prediction
-> verdict. Messages (``shm_ros.ros.convert``) and files (``shm_ros.io``) are converted to and from
these classes in one place each.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntFlag

import numpy as np


class SampleFlag(IntFlag):
    """Health bits of one sample of one channel (same values as ``shm_interfaces/msg/Window``)."""

    NONE = 0
    NAN = 1
    CLIPPED = 2
    SPIKE = 4
    DUPLICATE_STAMP = 8
    OUT_OF_ORDER = 16
    MISSING = 32


@dataclass
class Window:
    """One analysis window: aligned raw samples of several channels on a common sample grid.

    The window is half-open ``[start_ns, end_ns)`` with ``end_ns`` = last sample time + one period.
    ``samples`` are the raw float64 values recorded in m/s^2 (offsets such as gravity included).
    """

    window_id: str
    start_ns: int
    sample_rate_hz: float
    channel_names: list[str]
    samples: np.ndarray  # (n_samples, n_channels) float64
    flags: np.ndarray | None = None  # (n_samples, n_channels) uint8 of SampleFlag, None = clean
    channel_status: list[str] | None = None  # "ok" | "dead" | "clipped" | "noisy" | "dropped"
    temperature_c: float | None = None
    is_event: bool = False
    pga_m_s2: float = 0.0
    input_channel: str | None = None
    notes: list[str] = field(default_factory=list)
    # amplitude covariates (docs/interfaces.md §3), e.g. rms_accel_m_s2; identify copies them
    covariates: dict[str, float] = field(default_factory=dict)
    # what a triggered window is called: "earthquake", "high_amplitude" or "none"
    # (shm_ros.core.ingest.events.event_kind; "" = not classified)
    event_kind: str = ""

    @property
    def n_samples(self) -> int:
        return int(self.samples.shape[0])

    @property
    def end_ns(self) -> int:
        return self.start_ns + int(round(self.n_samples * 1e9 / self.sample_rate_hz))

    @property
    def duration_s(self) -> float:
        return self.n_samples / self.sample_rate_hz

    def stamps_ns(self) -> np.ndarray:
        k = np.arange(self.n_samples, dtype=np.int64)
        return self.start_ns + np.round(k * (1e9 / self.sample_rate_hz)).astype(np.int64)


@dataclass
class Mode:
    """One vibration mode; ``mode_shape`` is real, over the estimate's sensor ids, max |.| = +1."""

    frequency_hz: float
    damping_ratio: float
    mode_shape: np.ndarray
    mpc: float = float("nan")
    frequency_std_hz: float = float("nan")
    damping_std: float = float("nan")
    n_poles: int = 0
    mode_number: int = 0  # tracked identity, 1-based; 0 = not tracked
    frequency_spread_hz: float = float("nan")  # std of the frequency across model orders
    damping_spread: float = float("nan")  # std of the damping ratio across model orders


@dataclass
class ModalEstimate:
    """The modes identified in one window, sorted by frequency (docs/interfaces.md §3)."""

    window_id: str
    start_ns: int
    end_ns: int
    sensor_ids: list[str]
    modes: list[Mode]
    method: str = "ssi-cov"
    temperature_c: float | None = None
    covariates: dict[str, float] = field(default_factory=dict)
