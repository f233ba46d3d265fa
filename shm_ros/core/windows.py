"""From raw accelerometer messages to analysis windows: validation, alignment, windowing, events.

:class:`IngestCore` is fed message by message (live node) or array by array (offline bag reader,
importers) and emits finished :class:`~shm_ros.core.types.Window` objects. It never imports ROS:
the node and the bag reader only decode messages and call ``add_*``.

Time and windows (contracts section 1)
--------------------------------------
* Sample time is the message stamp. All channels share one sample grid ``origin + k * period``
  whose origin is the first sample of the current burst. A stamp is *snapped* to the nearest grid
  point when it lies strictly within ``snap_tolerance`` (default half) of a period of it; nothing is
  interpolated. A stamp that cannot be snapped (too far from every grid point, or beaten to its grid
  point by a closer stamp of the same channel) leaves its grid point empty: a gap.
* The grid starts at the nominal rate (a fitted Imu rate within 0.5 % of a whole number of Hz is
  taken as that number). When the stamps' clock drifts from it (a sensor crystal a little off),
  the period is re-fitted to the stamps of each window and the grid follows (info ``clock_drift``);
  separate clocks drifting apart still produce gaps.
* A burst ends where no channel has a sample for more than ``burst_pause_s`` (1 s). Inside a burst,
  windows of ``window_s`` are counted from the burst's first sample; a window is half-open
  ``[start, end)`` with ``end`` = last sample + one period.
* A window never spans a gap: a grid row where a (non-dropped) channel has no sample splits it.
  A piece (or burst remainder) shorter than half a window is dropped and reported.
* ``temperature_c`` is the mean of all temperature samples with ``start <= t < end`` (None if none).
* Values are the raw float64 samples in m/s^2 (times the sensor's ``sign``; AccelBlocks declared in
  g, cm/s^2 or mm/s^2 are converted by their declared factor). Offsets (gravity) and trends stay.

Fault policy (also in ``docs/ingest.md``)
-----------------------------------------
Never a silent repair, never an exception from one bad message: every fault produces a
:class:`Diagnostic` (level, source = topic/field, code, message, count).

=====================  ======================================  ===========================================
fault                  detected by                             handling
=====================  ======================================  ===========================================
NaN / Inf sample       ``~isfinite``                           kept as is (Inf -> stays), flag ``NAN``
clipped samples        runs >= ``clip_run`` at the channel's   flag ``CLIPPED``; status ``clipped``
                       extreme (flat top) or ``|x| >=
                       saturation_m_s2``
spike                  isolated sample > ``spike_k`` robust    flag ``SPIKE``; status ``noisy`` when
                       sigmas of the first differences from    flagged (NaN+spike) > ``noisy_fraction``
                       its 5-point median
duplicated stamp       two samples snap to one grid point      first kept, flag ``DUPLICATE_STAMP``,
                       with equal stamps                       copies counted and reported
out-of-order stamp     stamp < latest stamp of the channel     placed by its stamp, flag ``OUT_OF_ORDER``
clock jump backwards   out-of-order stamp in a region already  sample rejected (cannot be placed), reported
                       emitted (or colliding with kept ones)
unsnappable stamp      ``|t - grid| >= tol`` or collision      not placed -> its grid point is a gap
clock drift            significant trend of stamps vs grid     grid period re-fitted (info), no resampling
gap (one channel or    empty grid row                          window split there; pieces < window/2
all)                                                           dropped and reported
pause > burst_pause_s  no sample at all for > 1 s              burst boundary (info), remainder rule
channel mostly absent  coverage < ``min_coverage`` in a span   channel ``dropped`` for that window: present
                                                               values kept, rest NaN + ``MISSING``
dead / stuck channel   peak-to-peak <= ``dead_ptp_m_s2`` or    status ``dead`` (values kept)
                       longest constant run > half the window
implausible units      static level ~1 (g) / ~981 (cm/s^2) on  warning + window note; values NOT rescaled
                       a channel declared m/s^2, or the Imu's
                       |linear_acceleration| at rest
unknown units string   AccelBlock ``units``                    block rejected (error), nothing guessed
rate mismatch          block rate / channel rate != grid rate  block rejected / channel ``dropped`` for the
                                                               window (error); never resampled
malformed message      shape, types, non-finite stamp          message rejected (error)
unknown topic/channel  not in the channel map                  ignored, reported once (warning)
late sample            stamp before the last emitted window    rejected, reported
=====================  ======================================  ===========================================

Events: a window is an event (``is_event``) when the classic STA/LTA ratio of any usable channel
(after subtracting its median, in a copy) reaches ``sta_lta_on`` and/or its PGA reaches
``pga_threshold_m_s2``, depending on ``event_detector`` (``sta_lta`` by default; ``pga``, ``either``,
``both`` or ``none``); ``pga_m_s2`` is the largest
``|x - median|`` over usable channels.

Memory and speed: samples are buffered per channel in numpy chunks (no per-sample objects beyond
the short Python lists that :meth:`IngestCore.add_imu` appends to between consolidations).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any

import numpy as np

from shm_ros.core.types import SampleFlag, Window

AXES = {"x": 0, "y": 1, "z": 2}
G = 9.80665
#: Declared AccelBlock units -> factor to m/s^2 (lower-cased, spaces removed).
UNIT_FACTORS = {
    "": 1.0, "m/s^2": 1.0, "m/s2": 1.0, "m/s**2": 1.0, "ms^-2": 1.0, "m.s-2": 1.0, "ms-2": 1.0,
    "m/sec/sec": 1.0, "m/sec2": 1.0, "m/sec^2": 1.0,
    "g": G,
    "cm/s^2": 0.01, "cm/s2": 0.01, "cm/sec2": 0.01, "cm/sec^2": 0.01, "cm/sec/sec": 0.01, "gal": 0.01,
    "mm/s^2": 0.001, "mm/s2": 0.001, "mm/sec2": 0.001, "mg": G * 1e-3,
}

OK, WARN, ERROR = 0, 1, 2  # the levels of diagnostic_msgs/DiagnosticStatus
MAX_KEPT_DIAGNOSTICS = 10_000  # the newest are kept; counts are kept for all
LEVEL_NAMES = {OK: "info", WARN: "warning", ERROR: "error"}


def unit_factor(units: str) -> float | None:
    """Factor from declared ``units`` to m/s^2, or None when the string is not recognised."""
    return UNIT_FACTORS.get(units.strip().lower().replace(" ", ""))


def iso_utc(t_ns: int) -> str:
    """``2024-05-01T00:00:00.005Z`` (millisecond resolution, UTC)."""
    dt = datetime.fromtimestamp(t_ns // 1_000_000_000, tz=timezone.utc)
    ms = (t_ns % 1_000_000_000) // 1_000_000
    return dt.strftime("%Y-%m-%dT%H:%M:%S") + f".{ms:03d}Z"


# ----------------------------------------------------------------------------------------------
# channel map


@dataclass(frozen=True)
class ChannelSource:
    """Where one output channel (a sensor of the structure file) reads its samples.

    ``imu_topic``: last element of the ``.../accel/<id>`` Imu topic (None: not from an Imu);
    ``axis``: x | y | z of ``linear_acceleration``; ``block_channel``: AccelBlock channel name
    (None: not from an AccelBlock); ``sign`` multiplies the samples.
    """

    sensor_id: str
    imu_topic: str | None
    axis: str = "z"
    block_channel: str | None = None
    sign: float = 1.0


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
        """Each sensor from the Imu topic of its id (given axis, default z) or the block channel."""
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


# ----------------------------------------------------------------------------------------------
# configuration, diagnostics, results


@dataclass
class IngestConfig:
    """Settings of :class:`IngestCore`. Node parameters and CLI flags are generated from these
    fields (:data:`PARAMETER_HELP` holds the one-line help of each)."""

    window_s: float = 600.0
    sample_rate_hz: float | None = None
    burst_pause_s: float = 1.0
    snap_tolerance: float = 0.5
    max_latency_s: float = 2.0
    settle_s: float | None = None
    min_coverage: float = 0.5
    clip_run: int = 3
    saturation_m_s2: float | None = None
    dead_ptp_m_s2: float = 0.0
    spike_k: float = 12.0
    noisy_fraction: float = 0.01
    event_detector: str = "sta_lta"
    sta_s: float = 1.0
    lta_s: float = 30.0
    # narrow-band ambient response of a lightly damped structure reaches STA/LTA 5-9 within 10 min
    # (Rayleigh envelope); earthquakes go far above 10
    sta_lta_on: float = 10.0
    pga_threshold_m_s2: float = 0.5
    check_interval_s: float = 5.0
    rate_tolerance: float = 0.01
    max_repeats: int = 5

    def __post_init__(self) -> None:
        if not self.window_s > 0:
            raise ValueError(f"window_s must be > 0, got {self.window_s}")
        if not 0 < self.snap_tolerance <= 0.5:
            raise ValueError(f"snap_tolerance must be in (0, 0.5], got {self.snap_tolerance}")
        if self.event_detector not in ("sta_lta", "pga", "either", "both", "none"):
            raise ValueError("event_detector must be sta_lta|pga|either|both|none, "
                             f"got {self.event_detector!r}")
        if self.sample_rate_hz is not None and not self.sample_rate_hz > 0:
            raise ValueError(f"sample_rate_hz must be > 0, got {self.sample_rate_hz}")
        if self.settle_s is not None and not self.settle_s >= 0:
            raise ValueError(f"settle_s must be >= 0, got {self.settle_s}")


PARAMETER_HELP: dict[str, str] = {
    "window_s": "window length, s; long bursts are split into windows of this length",
    "sample_rate_hz": "grid sample rate, Hz (default: the first AccelBlock's, or fitted to Imu stamps)",
    "burst_pause_s": "a pause longer than this (no channel has data) ends a burst, s",
    "snap_tolerance": "a stamp snaps to a grid point strictly closer than this fraction of a period",
    "max_latency_s": "how long (stamp time) to wait for late channels before cutting; inf = at the end",
    "settle_s": "streaming: cut as soon as EVERY channel is this far (stamp time) past a window's end "
                "(default: max_latency_s, which then only bounds the wait for a lagging channel)",
    "min_coverage": "a channel with less than this fraction of a window's samples is dropped for it",
    "clip_run": "this many equal samples at a channel's extreme count as clipping",
    "saturation_m_s2": "|a| at or above this is flagged CLIPPED (default: only flat tops)",
    "dead_ptp_m_s2": "a channel whose peak-to-peak in a window is at most this is dead",
    "spike_k": "an isolated sample this many robust sigmas from its 5-point median is a spike",
    "noisy_fraction": "a channel with more NaN/spike samples than this fraction is 'noisy'",
    "event_detector": "earthquake/event trigger: sta_lta | pga | either | both | none",
    "sta_s": "STA window, s",
    "lta_s": "LTA window, s",
    "sta_lta_on": "STA/LTA ratio that triggers an event",
    "pga_threshold_m_s2": "peak |a - median| that triggers an event (pga, either, both)",
    "check_interval_s": "streaming: at most this often (stamp time) a burst end is looked for, s",
    "rate_tolerance": "relative difference of a channel's rate from the grid's that is reported",
    "max_repeats": "diagnostics of one code and source recorded between two windows (the rest counted)",
}


@dataclass
class Diagnostic:
    """One reported fault or event; ``level`` uses diagnostic_msgs values (0 OK, 1 WARN, 2 ERROR)."""

    level: int
    code: str
    source: str  # topic and field, e.g. "accel/s1.linear_acceleration.z" or "accel_block.samples[s3]"
    message: str
    stamp_ns: int | None = None
    count: int = 1

    def __str__(self) -> str:
        when = f" at {iso_utc(self.stamp_ns)}" if self.stamp_ns is not None else ""
        return f"[{LEVEL_NAMES.get(self.level, self.level)}] {self.code} {self.source}{when}: {self.message}"

    def to_dict(self) -> dict[str, Any]:
        return {"level": LEVEL_NAMES.get(self.level, str(self.level)), "code": self.code,
                "source": self.source, "message": self.message,
                "time": None if self.stamp_ns is None else iso_utc(self.stamp_ns), "count": self.count}


@dataclass
class DroppedSpan:
    """A stretch of aligned data that went into no window, and why."""

    start_ns: int
    end_ns: int
    n_samples: int
    reason: str


@dataclass
class IngestStats:
    samples_in: int = 0  # accepted channel samples handed to the core
    samples_windowed: int = 0  # channel samples placed in emitted windows
    samples_not_windowed: Counter = field(default_factory=Counter)  # reason -> channel samples
    messages_rejected: int = 0
    windows: int = 0


# ----------------------------------------------------------------------------------------------
# per-channel buffer


class _ChannelBuffer:
    """Samples of one output channel waiting to be cut, in numpy chunks (arrival order)."""

    __slots__ = ("t", "v", "f", "seq", "chunks", "last_max", "name")

    def __init__(self, name: str) -> None:
        self.name = name
        self.t = np.empty(0, np.int64)
        self.v = np.empty(0, np.float64)
        self.f = np.empty(0, np.uint8)
        self.seq = np.empty(0, np.int64)
        self.chunks: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self.last_max: int | None = None  # latest stamp seen (for OUT_OF_ORDER at arrival)

    def append(self, t: np.ndarray, v: np.ndarray, seq: np.ndarray) -> int:
        """Add samples; returns how many are out of order (stamp < an earlier stamp)."""
        if t.size == 0:
            return 0
        run = np.maximum.accumulate(t)
        prev = np.empty_like(run)
        prev[0] = np.iinfo(np.int64).min if self.last_max is None else self.last_max
        if t.size > 1:
            prev[1:] = run[:-1]
        if self.last_max is not None:
            np.maximum(prev, self.last_max, out=prev)
        ooo = t < prev
        f = np.where(ooo, np.uint8(SampleFlag.OUT_OF_ORDER), np.uint8(0)).astype(np.uint8)
        self.last_max = int(max(run[-1], prev[-1]))
        self.chunks.append((t, v, f, seq))
        return int(ooo.sum())

    def consolidate(self) -> None:
        if self.chunks:
            ts, vs, fs, ss = zip(*self.chunks)
            self.t = np.concatenate((self.t, *ts))
            self.v = np.concatenate((self.v, *vs))
            self.f = np.concatenate((self.f, *fs))
            self.seq = np.concatenate((self.seq, *ss))
            self.chunks.clear()

    def keep(self, mask: np.ndarray) -> None:
        self.t, self.v, self.f, self.seq = self.t[mask], self.v[mask], self.f[mask], self.seq[mask]

    @property
    def size(self) -> int:
        return int(self.t.size) + sum(c[0].size for c in self.chunks)


# ----------------------------------------------------------------------------------------------
# the core


class IngestCore:
    """Streaming validation, alignment and windowing; see the module docstring for the rules.

    Feed with :meth:`add_imu` / :meth:`add_imu_array`, :meth:`add_block`, :meth:`add_temperature`;
    collect finished windows with :meth:`pop_windows` and diagnostics with
    :meth:`pop_diagnostics`; call :meth:`flush` at the end of the stream (or :meth:`tick` from a
    timer so that a burst that has ended is emitted without waiting for new data).
    """

    def __init__(self, channel_map: ChannelMap, config: IngestConfig | None = None) -> None:
        self.map = channel_map
        self.config = config or IngestConfig()
        self.channels = channel_map.sensor_ids
        self.n_channels = len(self.channels)
        self._buf = [_ChannelBuffer(s) for s in self.channels]
        self._imu_routes: dict[str, list[tuple[int, int, float]]] = {}
        self._block_routes: dict[str, list[tuple[int, float]]] = {}
        for col, s in enumerate(channel_map.sources):
            if s.imu_topic is not None:
                self._imu_routes.setdefault(s.imu_topic, []).append((col, AXES[s.axis], float(s.sign)))
            if s.block_channel is not None:
                self._block_routes.setdefault(s.block_channel, []).append((col, float(s.sign)))
        self._imu_pending: dict[str, tuple[list[int], list[float], list[float], list[float]]] = {}
        self._imu_pending_n = 0
        self._busy = False  # inside a drain or a cut: no nested processing
        self._rate: float | None = self.config.sample_rate_hz
        self._rate_probe: dict[str, list[int]] = {}
        self._gravity_checked: set[str] = set()
        self._seq = 0
        self._chan_max: list[int | None] = [None] * self.n_channels
        self._due_ns: int | None = None  # process when the stream's final time passes this
        self._committed_ns: int | None = None  # grid time before which everything is emitted
        self._burst_origin: int | None = None
        self._anchor_t = 0
        self._anchor_k = 0
        self._period = 0.0
        self._burst_k = 0
        self._scan_ns: int | None = None  # stamps below this are scanned for pauses
        self._scan_last: int | None = None  # newest stamp of the open burst seen by the scan
        self._temps_t: list[int] = []
        self._temps_v: list[float] = []
        self._temp_t = np.empty(0, np.int64)
        self._temp_v = np.empty(0, np.float64)
        self._channel_factor: list[float | None] = [None] * self.n_channels  # declared units seen
        self._seen_source: list[str | None] = [None] * self.n_channels  # topic.field that fed it
        self._units_warned: set[tuple[int, str]] = set()
        self._windows: list[Window] = []
        self._diags: list[Diagnostic] = []
        self._diag_new = 0
        self._records_since: Counter = Counter()  # records per (code, source) since the last window
        self.diagnostic_counts: Counter = Counter()  # (code, source) -> occurrences
        self.dropped: list[DroppedSpan] = []
        self.stats = IngestStats()

    # ------------------------------------------------------------------ public feed API

    @property
    def sample_rate_hz(self) -> float | None:
        return self._rate

    def add_imu(self, topic_id: str, stamp_ns: int, ax: float, ay: float, az: float) -> None:
        """One ``sensor_msgs/Imu`` sample of topic ``.../accel/<topic_id>`` (m/s^2)."""
        pend = self._imu_pending.get(topic_id)
        if pend is None:
            if topic_id not in self._imu_routes:
                self._diag(WARN, "unknown_topic", f"accel/{topic_id}",
                           "Imu topic not in the structure's sensors: ignored", stamp_ns, once=True)
                return
            pend = self._imu_pending[topic_id] = ([], [], [], [])
        pend[0].append(stamp_ns)
        pend[1].append(ax)
        pend[2].append(ay)
        pend[3].append(az)
        self._imu_pending_n += 1
        if self._imu_pending_n >= 4096 or (self._rate is None and self._imu_pending_n >= 256):
            self._drain_imu()
        elif self._due_ns is not None and stamp_ns > self._due_ns + self._wait_ns:
            self._drain_imu()

    def add_imu_array(self, topic_id: str, stamps_ns: np.ndarray, xyz: np.ndarray) -> None:
        """Many Imu samples of one topic at once: ``stamps_ns`` (n,), ``xyz`` (n, 3) in m/s^2."""
        source = f"accel/{topic_id}"
        routes = self._imu_routes.get(topic_id)
        if routes is None:
            self._diag(WARN, "unknown_topic", source, "Imu topic not in the structure's sensors: ignored",
                       once=True)
            return
        try:
            t = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
            a = np.asarray(xyz, dtype=np.float64)
            if a.shape != (t.size, 3):
                raise ValueError(f"xyz has shape {a.shape}, expected ({t.size}, 3)")
        except (TypeError, ValueError) as exc:
            self._reject(source, f"malformed Imu samples: {exc}")
            return
        if t.size == 0:
            return
        self._probe_rate(topic_id, t)
        if topic_id not in self._gravity_checked and t.size >= 64:
            self._check_gravity(topic_id, a)
        seq = self._next_seq(t.size)
        for col, axis, sign in routes:
            v = a[:, axis] if sign == 1.0 else a[:, axis] * sign
            self._append(col, t, np.ascontiguousarray(v), seq,
                         f"{source}.linear_acceleration.{'xyz'[axis]}")
        self._after_add()

    def add_block(self, stamp_ns: int, sample_rate_hz: float, channel_names: Sequence[str],
                  samples: np.ndarray, units: str = "m/s^2", topic: str = "accel_block") -> None:
        """One ``AccelBlock``: sample k of ``samples`` (n, c) is at ``stamp_ns + k / rate``."""
        try:
            rate = float(sample_rate_hz)
            names = [str(c) for c in channel_names]
            x = np.asarray(samples, dtype=np.float64)
            if x.ndim == 1:
                if len(names) == 0 or x.size % len(names):
                    raise ValueError(f"{x.size} samples do not fill {len(names)} channels")
                x = x.reshape(-1, len(names))
            if x.ndim != 2 or x.shape[1] != len(names):
                raise ValueError(f"samples shape {x.shape} does not match {len(names)} channel names")
            if not (math.isfinite(rate) and rate > 0):
                raise ValueError(f"sample_rate_hz = {rate}")
            t0 = int(stamp_ns)
        except (TypeError, ValueError, OverflowError) as exc:
            self._reject(f"{topic}", f"malformed AccelBlock: {exc}", None)
            return
        factor = unit_factor(units or "")
        if factor is None:
            self._reject(f"{topic}.units", f"unknown units {units!r} (m/s^2, g, cm/s^2 or mm/s^2): "
                         "block rejected", t0)
            return
        if self._rate is None:
            self._rate = rate
            self._diag(OK, "sample_rate", f"{topic}.sample_rate_hz", f"grid rate {rate:g} Hz", t0)
        elif abs(rate - self._rate) > 1e-6 * self._rate:
            self._reject(f"{topic}.sample_rate_hz", f"block at {rate:g} Hz, grid at {self._rate:g} Hz: "
                         "not resampled, block rejected", t0)
            return
        n = x.shape[0]
        if n == 0:
            return
        t = t0 + np.round(np.arange(n) * (1e9 / rate)).astype(np.int64)
        seq = self._next_seq(n)
        for j, name in enumerate(names):
            routes = self._block_routes.get(name)
            if routes is None:
                self._diag(WARN, "unknown_channel", f"{topic}.channel_names[{name}]",
                           "channel not in the structure's sensors: ignored", t0, once=True)
                continue
            for col, sign in routes:
                v = x[:, j] * factor if factor != 1.0 else x[:, j].copy()
                if sign != 1.0:
                    v = v * sign
                if self._channel_factor[col] is None:
                    self._channel_factor[col] = factor
                self._append(col, t, v, seq, f"{topic}.samples[{name}]")
        self._after_add()

    def add_temperature(self, sensor_id: str, stamp_ns: int, value_c: float) -> None:
        """One ``sensor_msgs/Temperature`` sample (degrees C)."""
        try:
            t, v = int(stamp_ns), float(value_c)
        except (TypeError, ValueError, OverflowError) as exc:
            self._reject(f"temperature/{sensor_id}", f"malformed Temperature: {exc}")
            return
        if not math.isfinite(v):
            self._diag(WARN, "nan", f"temperature/{sensor_id}.temperature",
                       f"non-finite temperature {v}: not used in window means", t)
            return
        if self._committed_ns is not None and t < self._committed_ns:
            self._diag(OK, "late_temperature", f"temperature/{sensor_id}",
                       "temperature sample older than the last emitted window: not used", t)
            return
        self._temps_t.append(t)
        self._temps_v.append(v)

    def add_temperature_array(self, sensor_id: str, stamps_ns: np.ndarray, values_c: np.ndarray) -> None:
        for t, v in zip(np.asarray(stamps_ns).tolist(), np.asarray(values_c).tolist()):
            self.add_temperature(sensor_id, t, v)

    def report_error(self, source: str, message: str, level: int = ERROR, code: str = "input_error") -> None:
        """Record a fault found outside the core (e.g. a bag that cannot be read further)."""
        self._diag(level, code, source, message)

    def tick(self, now_ns: int) -> None:
        """Time has reached ``now_ns`` (stamp clock): close what cannot change any more."""
        if math.isfinite(self.config.max_latency_s):
            self.advance(int(now_ns) - self._latency_ns)

    def advance(self, final_ns: int) -> None:
        """Every sample stamped before ``final_ns`` has been fed: cut what that completes.

        Readers that know their order (a bag read in time order) call this with
        ``max_latency_s=inf``; a live stream relies on ``max_latency_s`` instead.
        """
        if self._rate is None:
            self._drain_imu()
            if self._rate is None:
                return
        maxima = [m for m in self._chan_max if m is not None]
        stopped = bool(maxima) and final_ns - max(maxima) > self.config.burst_pause_s * 1e9
        if self._due_ns is None or int(final_ns) >= self._due_ns or (
                stopped and any(b.size for b in self._buf)):
            self._process(int(final_ns))

    def flush(self) -> list[Window]:
        """End of stream: cut everything still buffered; returns (and pops) all finished windows."""
        self._drain_imu()
        self._process(None)
        self._temp_t = np.empty(0, np.int64)
        self._temp_v = np.empty(0, np.float64)
        return self.pop_windows()

    def pop_windows(self) -> list[Window]:
        out, self._windows = self._windows, []
        return out

    def pop_diagnostics(self) -> list[Diagnostic]:
        """Diagnostics recorded since the last call (for a node to publish)."""
        out = self._diags[len(self._diags) - self._diag_new:] if self._diag_new else []
        self._diag_new = 0
        return out

    @property
    def diagnostics(self) -> list[Diagnostic]:
        """The diagnostics kept (the newest ``MAX_KEPT_DIAGNOSTICS`` or more; repeats of one code
        and source beyond ``max_repeats`` between two windows are only counted)."""
        return list(self._diags)

    # ------------------------------------------------------------------ internals: feeding

    @property
    def _wait_ns(self) -> int:
        """Stamp time past a due point after which buffered samples are worth a look."""
        settle = self.config.settle_s
        return self._latency_ns if settle is None else min(self._latency_ns, int(settle * 1e9))

    @property
    def _latency_ns(self) -> int:
        lat = self.config.max_latency_s
        return 2**62 if not math.isfinite(lat) else int(lat * 1e9)

    def _diag(self, level: int, code: str, source: str, message: str, stamp_ns: int | None = None,
              count: int = 1, once: bool = False) -> None:
        key = (code, source)
        first = key not in self.diagnostic_counts
        self.diagnostic_counts[key] += count
        # records of one (code, source) are limited between two emitted windows (so that a live
        # node keeps reporting a fault that goes on), and to one for "once" notices
        if (first if once else self._records_since[key] < self.config.max_repeats):
            self._records_since[key] += 1
            self._diags.append(Diagnostic(level, code, source, message, stamp_ns, count))
            self._diag_new += 1
            if len(self._diags) > 2 * MAX_KEPT_DIAGNOSTICS:  # bounded memory in a long-running node
                del self._diags[:MAX_KEPT_DIAGNOSTICS]
                self._diag_new = min(self._diag_new, len(self._diags))

    def _reject(self, source: str, message: str, stamp_ns: int | None = None) -> None:
        self.stats.messages_rejected += 1
        self._diag(ERROR, "rejected", source, message, stamp_ns)

    def _next_seq(self, n: int) -> np.ndarray:
        s = np.arange(self._seq, self._seq + n, dtype=np.int64)
        self._seq += n
        return s

    def _drain_imu(self) -> None:
        if not self._imu_pending_n:
            return
        pending, self._imu_pending = self._imu_pending, {}
        self._imu_pending_n = 0
        busy, self._busy = self._busy, True  # every topic in first, then one look at the windows
        try:
            self._drain_topics(pending)
        finally:
            self._busy = busy
        self._after_add()

    def _drain_topics(self, pending: dict) -> None:
        for topic_id, (ts, xs, ys, zs) in pending.items():
            if not ts:
                continue
            try:
                t = np.asarray(ts, dtype=np.int64)
            except (TypeError, ValueError, OverflowError):
                # a bad stamp: fall back to one by one so that only the bad samples are rejected
                good = []
                for i, s in enumerate(ts):
                    try:
                        int(s)
                        good.append(i)
                    except (TypeError, ValueError, OverflowError):
                        self._reject(f"accel/{topic_id}.header.stamp", f"bad stamp {s!r}")
                t = np.asarray([ts[i] for i in good], dtype=np.int64)
                xs, ys, zs = ([v[i] for i in good] for v in (xs, ys, zs))
            try:
                xyz = np.column_stack((np.asarray(xs, np.float64), np.asarray(ys, np.float64),
                                       np.asarray(zs, np.float64)))
            except (TypeError, ValueError) as exc:
                self._reject(f"accel/{topic_id}.linear_acceleration", f"non-numeric values: {exc}")
                continue
            self.add_imu_array(topic_id, t, xyz)

    def _check_gravity(self, topic_id: str, a: np.ndarray) -> None:
        """An Imu at rest reads |a| = g on its three axes together: ~1 means g, ~981 cm/s^2."""
        self._gravity_checked.add(topic_id)
        mag = float(np.nanmedian(np.sqrt(np.sum(a * a, axis=1))))
        guess = None
        if 0.85 < mag < 1.15:
            guess = "g"
        elif 850 < mag < 1150:
            guess = "cm/s^2"
        elif 8500 < mag < 11500:
            guess = "mm/s^2"
        if guess:
            self._diag(WARN, "units", f"accel/{topic_id}.linear_acceleration",
                       f"|linear_acceleration| = {mag:.4g} at rest looks like {guess}, not m/s^2 "
                       "(REP-145: m/s^2 with gravity): values NOT rescaled")
        elif not 0 < mag < 50 and math.isfinite(mag):
            self._diag(WARN, "units", f"accel/{topic_id}.linear_acceleration",
                       f"|linear_acceleration| = {mag:.4g} m/s^2 is implausible for a structure "
                       "(expected about 9.81 with gravity): values NOT rescaled")

    def _probe_rate(self, topic_id: str, t: np.ndarray) -> None:
        if self._rate is not None:
            return
        probe = self._rate_probe.setdefault(topic_id, [])
        probe.extend(t[:1024].tolist())
        if len(probe) >= 64:
            rate = estimate_rate(np.asarray(probe, np.int64))
            if rate is not None:
                self._rate = rate
                self._diag(OK, "sample_rate", f"accel/{topic_id}.header.stamp",
                           f"grid rate {rate:g} Hz (fitted to the stamps)", int(t[0]))

    def _append(self, col: int, t: np.ndarray, v: np.ndarray, seq: np.ndarray, source: str) -> None:
        buf = self._buf[col]
        self._seen_source[col] = source
        if self._committed_ns is not None:
            late = t < self._committed_ns
            if late.any():
                n = int(late.sum())
                self.stats.samples_not_windowed["late"] += n
                self._diag(WARN, "late_sample", source,
                           f"{n} sample(s) stamped before the last emitted window (clock jump "
                           "backwards or late delivery): rejected", int(t[late][0]), n)
                keep = ~late
                t, v, seq = t[keep], v[keep], seq[keep]
                if t.size == 0:
                    return
        n_ooo = buf.append(t, v, seq)
        if n_ooo:
            self._diag(WARN, "out_of_order", source,
                       f"{n_ooo} stamp(s) earlier than a previous stamp: placed by stamp, flagged "
                       "OUT_OF_ORDER", int(t[0]), n_ooo)
        self.stats.samples_in += int(t.size)
        tmax = int(t.max())
        cm = self._chan_max[col]
        self._chan_max[col] = tmax if cm is None else max(cm, tmax)

    def _final_ns(self) -> int | None:
        maxima = [m for m in self._chan_max if m is not None]
        if not maxima:
            return None
        if not math.isfinite(self.config.max_latency_s):
            return None  # offline, fed channel by channel: everything waits for flush()
        # the median channel, so that one channel with a clock jump forward cannot close windows
        final = int(np.median(maxima)) - self._latency_ns
        settle = self.config.settle_s
        if settle is not None and len(maxima) == self.n_channels:
            # every expected channel has reached ``end + settle``: nothing earlier can still come
            # (each channel's own stamps arrive in order); a silent or lagging channel holds this
            # back, and then only the median rule above closes the window
            final = max(final, min(maxima) - int(settle * 1e9))
        return final

    def _after_add(self) -> None:
        if self._rate is None or self._busy:
            return
        final = self._final_ns()
        if final is not None and (self._due_ns is None or final >= self._due_ns):
            self._process(final)

    # ------------------------------------------------------------------ internals: cutting

    def _period_ns(self) -> float:
        assert self._rate is not None
        return 1e9 / self._rate

    def _window_len(self) -> int:
        assert self._rate is not None
        return max(1, int(round(self.config.window_s * self._rate)))

    def _process(self, final_ns: int | None) -> None:
        """Cut every window whose data is final (``final_ns`` None = end of stream)."""
        busy, self._busy = self._busy, True
        try:
            self._process_now(final_ns)
        finally:
            self._busy = busy

    def _process_now(self, final_ns: int | None) -> None:
        self._drain_imu()
        if self._rate is None:
            if final_ns is None and any(b.size for b in self._buf):
                self._diag(ERROR, "no_rate", "accel", "too few samples to know the sample rate: "
                           "nothing windowed (set sample_rate_hz)")
            return
        for b in self._buf:
            b.consolidate()
        if self._temps_t:
            self._temp_t = np.concatenate((self._temp_t, np.asarray(self._temps_t, np.int64)))
            self._temp_v = np.concatenate((self._temp_v, np.asarray(self._temps_v, np.float64)))
            self._temps_t, self._temps_v = [], []
        W = self._window_len()
        pause_ns = self.config.burst_pause_s * 1e9
        end_of_stream = final_ns is None
        fin = np.iinfo(np.int64).max if end_of_stream else int(final_ns)
        while True:
            if self._burst_origin is None:
                firsts = [int(b.t.min()) for b in self._buf if b.t.size]
                if not firsts or min(firsts) >= fin:
                    break
                self._open_burst(min(firsts))
            k0 = self._burst_k
            span_start = self._ge(k0)  # stamps in [span_start, span_end) snap into this window
            span_end = self._ge(k0 + W)
            lim = min(span_end, fin)
            lo = span_start if self._scan_ns is None else max(span_start, self._scan_ns)
            parts = [b.t[(b.t >= lo) & (b.t < lim)] for b in self._buf]
            u = np.sort(np.concatenate(parts))  # duplicates are harmless for finding pauses
            if u.size:
                prev = self._scan_last
                seq_u = u if prev is None else np.concatenate(([prev], u))
                jumps = np.flatnonzero(np.diff(seq_u) > pause_ns)
                if jumps.size:
                    end_stamp = int(seq_u[jumps[0]])
                    if end_stamp >= span_start:
                        self._cut(k0, self._slot(end_stamp) + 1, "pause", end_stamp)
                    self._close_burst()
                    continue
                self._scan_last = int(u[-1])
            self._scan_ns = int(lim)
            last = self._scan_last  # newest stamp of the burst so far
            if fin >= span_end:  # everything that snaps into this window is final
                later = [b.t[(b.t >= span_end) & (b.t < fin)] for b in self._buf]
                later = [x.min() for x in later if x.size]
                nxt = int(min(later)) if later else None
                if last is None:  # (cannot happen: a burst opens on a sample) - close defensively
                    self._close_burst()
                    continue
                ended = (nxt - last > pause_ns) if nxt is not None else (
                    end_of_stream or fin - last > pause_ns)
                if nxt is None and not ended:
                    break  # the burst may go on: wait
                if ended:
                    if last >= span_start:
                        self._cut(k0, self._slot(last) + 1, "end" if end_of_stream else "pause", last)
                    self._close_burst()
                    continue
                self._cut(k0, k0 + W, None)
                self._burst_k = k0 + W
                continue
            if last is not None and fin - last > pause_ns:
                if last >= span_start:
                    self._cut(k0, self._slot(last) + 1, "pause", last)
                self._close_burst()
                continue
            break
        # when to try again: the end of the open window, or a pause after the newest sample;
        # at most every check interval of stream time, so that a long window is not rescanned often
        if self._burst_origin is not None:
            due = self._gt(self._burst_k + W)
            if self._scan_last is not None:
                due = min(due, max(self._scan_last + int(pause_ns) + 1,
                                   fin + int(self.config.check_interval_s * 1e9)))
            self._due_ns = due
        else:
            firsts = [int(b.t.min()) for b in self._buf if b.t.size]
            self._due_ns = None if not firsts else _grid(min(firsts), W, self._period_ns())
        if self._temp_t.size and self._committed_ns is not None:
            keep = self._temp_t >= self._committed_ns
            self._temp_t, self._temp_v = self._temp_t[keep], self._temp_v[keep]

    # The grid of the open burst: grid point k is at anchor_t + (k - anchor_k) * period. It starts
    # at the burst's first sample with the nominal period and follows the stamps' clock when it
    # drifts (see _track), so long bursts from a clock a little off the nominal rate stay aligned.
    def _gt(self, k: int) -> int:
        return _grid(self._anchor_t, k - self._anchor_k, self._period)

    def _ge(self, k: int) -> int:
        return _edge(self._anchor_t, k - self._anchor_k, self._period)

    def _slot(self, t: int) -> int:
        return self._anchor_k + int(np.rint((t - self._anchor_t) / self._period))

    def _open_burst(self, origin: int) -> None:
        self._burst_origin = origin
        self._anchor_t, self._anchor_k, self._period = origin, 0, self._period_ns()
        self._burst_k = 0
        self._scan_ns = None
        self._scan_last = None
        self._diag(OK, "burst", "accel", "burst starts", origin)

    def _close_burst(self) -> None:
        self._burst_origin = None
        self._burst_k = 0
        self._scan_ns = None
        self._scan_last = None

    def _track(self, k0: int, k1: int) -> None:
        """Follow the stamps' clock: fit t = a + b (k - k0) to the stamps of grid rows [k0, k1)
        (all channels, outliers beyond half a period left out, the fit widened step by step as
        in :func:`estimate_rate`); when it departs from the grid by more than a tenth of a period
        at either end, the grid from k0 on is re-anchored to the fit. Nothing is resampled: this
        only moves the common grid that stamps are snapped to."""
        P = self._period
        lo, hi = self._ge(k0), self._ge(k1)
        parts = [b.t[(b.t >= lo) & (b.t < hi)] for b in self._buf]
        ts = np.concatenate(parts) if parts else np.empty(0, np.int64)
        if ts.size > 100_000:  # a fit needs no more; keeps a 10-minute window cheap
            ts = ts[:: int(math.ceil(ts.size / 100_000))]
        ts = np.sort(ts)
        if ts.size < 64:
            return
        t0 = self._gt(k0)
        rel = (ts - t0).astype(np.float64)
        a, b = 0.0, P
        n_rows = k1 - k0
        if n_rows < 64:
            return
        rows, stages = 64, []
        while rows < n_rows:
            stages.append(rows)
            rows *= 4
        stages.append(n_rows)
        se_b = np.inf
        for rows in stages:  # widen the fit over 64, 256, ... rows as the period gets known
            m = int(np.searchsorted(rel, (rows - 0.5) * P))
            r, kk = rel[:m], np.rint((rel[:m] - a) / b)
            res = r - (a + b * kk)
            good = np.abs(res) < 0.5 * b
            if good.sum() < 32 or np.ptp(kk[good]) < 32:
                return
            kg, rg = kk[good], r[good]
            kc, rc = kg - kg.mean(), rg - rg.mean()
            spread = float(kc @ kc)
            if spread <= 0:
                return
            b = float(kc @ rc) / spread  # least-squares line, closed form
            a = float(rg.mean() - b * kg.mean())
            se_b = float(np.std(rc - b * kc)) / math.sqrt(spread)
        # the period follows a trend of more than a tenth of a period over the window; the grid
        # point k0 stays put unless the stamps sit a quarter period or more away from it (constant
        # offsets between IMUs are what the half-period tolerance is for)
        # (a significant trend only: 4 standard errors of the fitted period)
        slope_drift = abs(b - P) * n_rows if abs(b - P) > 4 * se_b else 0.0
        shift = int(round(a)) if abs(a) >= 0.25 * P else 0
        if (slope_drift > 0.1 * P or shift) and abs(b - P) < self.config.rate_tolerance * P:
            self._anchor_t, self._anchor_k = t0 + shift, k0
            self._period = float(b) if slope_drift > 0.1 * P else P
            self._diag(OK, "clock_drift", "accel",
                       f"stamps run at {1e9 / b:.7g} Hz, {a / 1e6:.3g} ms off the grid (grid was "
                       f"{1e9 / P:.7g} Hz): the grid follows the stamps' clock from here", t0)

    def _cut(self, k0: int, k1: int, why: str | None, last_stamp: int | None = None) -> None:
        """Place the samples of grid rows [k0, k1) and emit the window(s) they make (``last_stamp``:
        the burst's last stamp when it ends here)."""
        if k1 <= k0:
            return
        self._track(k0, k1)
        if last_stamp is not None:
            k1 = max(k0 + 1, self._slot(last_stamp) + 1)  # on the (possibly re-anchored) grid
        P = self._period
        at, ak = self._anchor_t, self._anchor_k
        W = self._window_len()
        n = k1 - k0
        C = self.n_channels
        tol = self.config.snap_tolerance * P
        vals = np.full((n, C), np.nan)
        flags = np.zeros((n, C), np.uint8)
        filled = np.zeros((n, C), bool)
        span_start = self._ge(k0)
        span_end = self._ge(k1)
        notes: list[str] = []
        mismatch = np.zeros(C, bool)
        for c, b in enumerate(self._buf):
            sel = (b.t < span_end)
            if not sel.any():
                continue
            t, v, f, seq = b.t[sel], b.v[sel], b.f[sel], b.seq[sel]
            b.keep(~sel)
            before = t < span_start
            if before.any():  # belongs to an earlier, already cut span
                nb = int(before.sum())
                self.stats.samples_not_windowed["late"] += nb
                self._diag(WARN, "late_sample", self._src(c),
                           f"{nb} sample(s) stamped inside an already cut span (clock jump "
                           "backwards?): rejected", int(t[before][0]), nb)
                keep = ~before
                t, v, f, seq = t[keep], v[keep], f[keep], seq[keep]
                if t.size == 0:
                    continue
            rel = (t - at).astype(np.float64)
            k = np.rint(rel / P).astype(np.int64)
            resid = np.abs(rel - k * P)
            k += ak
            snappable = resid < tol
            n_bad = int((~snappable).sum())
            # collisions: best (smallest residual, then earliest arrival) wins each grid row
            order = np.lexsort((seq, resid, k))
            order = order[snappable[order]]
            ks = k[order]
            first = np.ones(ks.size, bool)
            first[1:] = ks[1:] != ks[:-1]
            win = order[first]
            lose = order[~first]
            rows = k[win] - k0
            vals[rows, c] = v[win]
            flags[rows, c] = f[win]
            filled[rows, c] = True
            if lose.size:
                # losers with the same stamp as the winner are duplicated stamps
                win_t = np.repeat(t[win], np.diff(np.append(np.flatnonzero(first), ks.size)))
                lose_t_sorted = t[order][~first]
                dup = lose_t_sorted == win_t[~first]
                ndup = int(dup.sum())
                if ndup:
                    dup_rows = k[order][~first][dup] - k0
                    flags[dup_rows, c] |= np.uint8(SampleFlag.DUPLICATE_STAMP)
                    differ = int((v[order][~first][dup] != vals[dup_rows, c]).sum())
                    self._diag(WARN, "duplicate_stamp", self._src(c),
                               f"{ndup} duplicated stamp(s): first kept and flagged DUPLICATE_STAMP, "
                               f"{ndup} copies not placed ({differ} with a different value)",
                               int(t[order][~first][dup][0]), ndup)
                    notes.append(f"{self.channels[c]}: {ndup} duplicated stamps")
                    self.stats.samples_not_windowed["duplicate"] += ndup
                ncol = int((~dup).sum())
                if ncol:
                    self._diag(WARN, "unsnappable", self._src(c),
                               f"{ncol} stamp(s) compete for a grid point already taken by a closer "
                               "stamp: not placed (gap)", int(t[order][~first][~dup][0]), ncol)
                    self.stats.samples_not_windowed["unsnappable"] += ncol
            if n_bad:
                self._diag(WARN, "unsnappable", self._src(c),
                           f"{n_bad} stamp(s) farther than {self.config.snap_tolerance:g} period "
                           "from the grid: not placed (gap)", int(t[~snappable][0]), n_bad)
                self.stats.samples_not_windowed["unsnappable"] += n_bad
            # the rate of this channel, for a clear message when it differs from the grid
            if t.size > 64:
                r = estimate_rate(t[:4096], nominal=False)
                if r is not None:
                    if abs(r - self._rate) > self.config.rate_tolerance * self._rate:
                        mismatch[c] = True
                        self._diag(ERROR, "rate_mismatch", self._src(c),
                                   f"samples at {r:.4g} Hz, grid at {self._rate:g} Hz: not resampled; "
                                   "the channel is dropped for this window", int(t[0]))
        self._committed_ns = span_end
        # channels mostly absent are dropped for this span instead of splitting it everywhere
        cover = filled.mean(axis=0)
        dropped = (cover < self.config.min_coverage) | mismatch
        for c in np.flatnonzero(dropped):
            self._diag(WARN, "channel_dropped", self._src(c),
                       f"{'wrong rate' if mismatch[c] else f'only {cover[c]:.0%} of the samples present'}: "
                       "channel dropped for "
                       f"[{iso_utc(self._gt(k0))}, {iso_utc(self._gt(k1))})", self._gt(k0))
            flags[~filled[:, c], c] |= np.uint8(SampleFlag.MISSING)
        active = ~dropped
        if active.any():
            row_ok = filled[:, active].all(axis=1)
        else:
            row_ok = np.zeros(n, bool)
        # contiguous runs of complete rows
        edges = np.diff(np.concatenate(([0], row_ok.view(np.int8), [0])))
        starts = np.flatnonzero(edges == 1)
        ends = np.flatnonzero(edges == -1)
        min_len = W / 2.0
        gap_rows = ~row_ok
        if gap_rows.any() and active.any():
            lost = int(filled[gap_rows].sum())
            for c in np.flatnonzero(active):
                miss = ~filled[:, c]
                if miss.any():
                    first_miss = int(np.flatnonzero(miss)[0])
                    self._diag(WARN, "gap", self._src(c),
                               f"{int(miss.sum())} grid point(s) without a sample: window split there",
                               self._gt(k0 + first_miss), int(miss.sum()))
            if lost:
                self.stats.samples_not_windowed["gap_rows"] += lost
        for s, e in zip(starts.tolist(), ends.tolist()):
            m = e - s
            t_s = self._gt(k0 + s)
            t_e = self._gt(k0 + e)
            if m < min_len:
                reason = "remainder of burst" if (e == n and why is not None) else "piece between gaps"
                self.dropped.append(DroppedSpan(t_s, t_e, m, f"{reason} shorter than half a window"))
                self.stats.samples_not_windowed["short_piece"] += int(filled[s:e].sum())
                self._diag(OK if reason.startswith("remainder") else WARN, "remainder_dropped",
                           "accel", f"{m} samples ({m / self._rate:.3g} s, {reason}) shorter than "
                           f"half a window ({min_len / self._rate:.3g} s): dropped", t_s, 1)
                continue
            piece_notes = list(notes)
            if s > 0:
                piece_notes.append("starts after a gap (window split there)")
            if e < n:
                piece_notes.append("ends at a gap (window split there)")
            self._emit(t_s, vals[s:e], flags[s:e], dropped, piece_notes)

    def _src(self, c: int) -> str:
        seen = self._seen_source[c]
        if seen is not None:
            return f"{seen} (sensor {self.channels[c]})"
        s = self.map.sources[c]
        out = []
        if s.imu_topic is not None:
            out.append(f"accel/{s.imu_topic}.linear_acceleration.{s.axis}")
        if s.block_channel is not None:
            out.append(f"accel_block.samples[{s.block_channel}]")
        return " | ".join(out) + f" (sensor {s.sensor_id})"

    # ------------------------------------------------------------------ internals: one window

    def _emit(self, start_ns: int, vals: np.ndarray, flags: np.ndarray, dropped: np.ndarray,
              notes: list[str]) -> None:
        cfg = self.config
        rate = 1e9 / self._period  # the grid's rate (the nominal one unless the clock drifted)
        n, C = vals.shape
        vals = np.ascontiguousarray(vals)
        flags = flags.copy()
        status = ["dropped" if dropped[c] else "ok" for c in range(C)]
        end_ns = start_ns + int(round(n * 1e9 / rate))
        where = f"[{iso_utc(start_ns)}, {iso_utc(end_ns)})"
        for c in range(C):
            if dropped[c]:
                notes.append(f"{self.channels[c]}: dropped (too few samples)")
                continue
            x = vals[:, c]
            finite = np.isfinite(x)
            n_nan = int((~finite).sum())
            if n_nan:
                flags[~finite, c] |= np.uint8(SampleFlag.NAN)
                self._diag(WARN, "nan", self._src(c), f"{n_nan} NaN/Inf sample(s) in {where}: "
                           "kept and flagged NAN", start_ns, n_nan)
                notes.append(f"{self.channels[c]}: {n_nan} NaN/Inf samples")
            xf = x[finite]
            if xf.size == 0:
                status[c] = "dead"
                self._diag(WARN, "dead_channel", self._src(c), f"no finite sample in {where}", start_ns)
                notes.append(f"{self.channels[c]}: dead (no finite sample)")
                continue
            lo, hi = float(xf.min()), float(xf.max())
            if hi - lo <= cfg.dead_ptp_m_s2 or _longest_constant_run(xf) > xf.size / 2:
                status[c] = "dead"
                self._diag(WARN, "dead_channel", self._src(c),
                           f"stuck/zero variance (peak-to-peak {hi - lo:.3g} m/s^2) in {where}: "
                           "marked dead, values kept", start_ns)
                notes.append(f"{self.channels[c]}: dead (stuck)")
                continue
            med = float(np.median(xf))
            clip = _clipped(x, lo, hi, med, cfg.clip_run)
            if cfg.saturation_m_s2 is not None:
                clip |= np.abs(np.nan_to_num(x, nan=0.0)) >= cfg.saturation_m_s2
            n_clip = int(clip.sum())
            if n_clip:
                flags[clip, c] |= np.uint8(SampleFlag.CLIPPED)
                status[c] = "clipped"
                self._diag(WARN, "clipped", self._src(c), f"{n_clip} sample(s) flat-topped at "
                           f"{lo:.4g}/{hi:.4g} m/s^2 in {where}: flagged CLIPPED", start_ns, n_clip)
                notes.append(f"{self.channels[c]}: {n_clip} clipped samples")
            spikes = _spikes(x, finite, cfg.spike_k, rate) & ~clip
            n_sp = int(spikes.sum())
            if n_sp:
                flags[spikes, c] |= np.uint8(SampleFlag.SPIKE)
                self._diag(WARN, "spike", self._src(c), f"{n_sp} isolated spike(s) in {where}: "
                           "flagged SPIKE", start_ns, n_sp)
                notes.append(f"{self.channels[c]}: {n_sp} spikes")
            if status[c] == "ok" and (n_sp + n_nan) > cfg.noisy_fraction * n:
                status[c] = "noisy"
            self._check_units(c, med, lo, hi, start_ns, notes)
        n_missing_flag = int(((flags & SampleFlag.MISSING) != 0).sum())
        if n_missing_flag:
            notes.append(f"{n_missing_flag} missing samples of dropped channels set to NaN")
        # temperature
        temp = None
        if self._temp_t.size:
            inside = (self._temp_t >= start_ns) & (self._temp_t < end_ns)
            if inside.any():
                temp = float(self._temp_v[inside].mean())
        is_event, pga = self._detect_event(vals, status)
        in_ch = self.map.input_sensor if self.map.input_sensor in self.channels else None
        w = Window(
            window_id=iso_utc(start_ns),
            start_ns=int(start_ns),
            sample_rate_hz=rate,
            channel_names=list(self.channels),
            samples=vals,
            flags=flags if flags.any() else None,
            channel_status=status,
            temperature_c=temp,
            is_event=is_event,
            pga_m_s2=pga,
            input_channel=in_ch,
            notes=notes,
        )
        if is_event:
            self._diag(OK, "event", "accel", f"event detected in {where}, PGA {pga:.3g} m/s^2", start_ns)
        self.stats.windows += 1
        self._records_since.clear()
        self.stats.samples_windowed += n * C - int(((flags & SampleFlag.MISSING) != 0).sum())
        self._windows.append(w)

    def _check_units(self, c: int, med: float, lo: float, hi: float, t: int, notes: list[str]) -> None:
        factor = self._channel_factor[c]
        if factor not in (None, 1.0):
            return  # declared units were converted; the hint below is about undeclared ones
        level = abs(med)
        guess = None
        if 0.85 < level < 1.15 and max(abs(lo), abs(hi)) < 4.0:
            guess = "g"
        elif 850 < level < 1150:
            guess = "cm/s^2"
        elif 8500 < level < 11500:
            guess = "mm/s^2"
        elif max(abs(lo), abs(hi)) > 2000:
            guess = "something other than m/s^2 (|a| > 2000 m/s^2)"
        if guess and (c, guess) not in self._units_warned:
            self._units_warned.add((c, guess))
            self._diag(WARN, "units", self._src(c),
                       f"static level {med:.4g} looks like {guess}, not m/s^2: values NOT rescaled; "
                       "check the driver or the AccelBlock units field", t)
        if guess:
            notes.append(f"{self.channels[c]}: units look like {guess}")

    def _detect_event(self, vals: np.ndarray, status: list[str]) -> tuple[bool, float]:
        cfg = self.config
        rate = float(self._rate)  # type: ignore[arg-type]
        usable = [c for c, s in enumerate(status) if s in ("ok", "noisy", "clipped")]
        if not usable:
            return False, 0.0
        x = vals[:, usable]
        x = np.where(np.isfinite(x), x, np.nan)
        x = x - np.nanmedian(x, axis=0)
        x = np.nan_to_num(x, nan=0.0)
        pga = float(np.abs(x).max()) if x.size else 0.0
        trig_pga = pga >= cfg.pga_threshold_m_s2
        trig_sl = False
        if cfg.event_detector in ("sta_lta", "either", "both"):
            trig_sl = float(sta_lta(x, rate, cfg.sta_s, cfg.lta_s).max(initial=0.0)) >= cfg.sta_lta_on
        if cfg.event_detector == "sta_lta":
            return trig_sl, pga
        if cfg.event_detector == "pga":
            return trig_pga, pga
        if cfg.event_detector == "either":
            return trig_sl or trig_pga, pga
        if cfg.event_detector == "both":
            return trig_sl and trig_pga, pga
        return False, pga


# ----------------------------------------------------------------------------------------------
# detectors (plain numpy)


def estimate_rate(stamps: np.ndarray, nominal: bool = True) -> float | None:
    """Sample rate (Hz) of jittered stamps: the median interval over 16 samples, refined by
    least-squares fits over growing spans; within 0.5 % of a whole number of Hz it is rounded
    (``nominal``). None when fewer than 17 distinct stamps."""
    ts = np.sort(np.asarray(stamps, np.int64))
    ts = ts[np.concatenate(([True], np.diff(ts) > 0))]
    if ts.size < 17:
        return None
    lag = 16
    slope = float(np.median((ts[lag:] - ts[:-lag]) / lag))
    if not slope > 0:
        return None
    rel = (ts - ts[0]).astype(np.float64)
    for m in (64, 256, ts.size):
        m = min(m, ts.size)
        k = np.rint(rel[:m] / slope)
        if k[-1] > 0:
            slope = float(np.polyfit(k, rel[:m], 1)[0])
    rate = 1e9 / slope
    if nominal and abs(rate - round(rate)) < 5e-3 * rate:
        rate = float(round(rate))
    return rate


def _grid(origin: int, k: int, period_ns: float) -> int:
    """Time of grid point ``k`` (integer nanoseconds; float64 alone cannot hold epoch ns)."""
    return origin + int(round(k * period_ns))


def _edge(origin: int, k: int, period_ns: float) -> int:
    """First integer stamp that snaps to grid point ``k`` or later (half a period before it)."""
    return origin + int(math.ceil(k * period_ns - period_ns / 2))


def sta_lta(x: np.ndarray, rate: float, sta_s: float, lta_s: float) -> np.ndarray:
    """Classic STA/LTA of ``x`` (n,) or (n, c): trailing means of x^2 over ``sta_s`` and ``lta_s``.

    While fewer than ``lta_s`` seconds precede a sample the LTA is the mean over all of them (at
    least ``2 * sta_s``; zeros before), so that a record that starts shortly before an earthquake
    still triggers. Written out because it is a few lines of cumulative sums.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    ns, nl = max(1, int(round(sta_s * rate))), max(1, int(round(lta_s * rate)))
    n = x.shape[0]
    out = np.zeros_like(x)
    first = min(nl, 2 * ns)
    if n < first:
        return out
    cs = np.vstack((np.zeros((1, x.shape[1])), np.cumsum(x * x, axis=0)))
    idx = np.arange(first, n + 1)
    lo = np.maximum(idx - nl, 0)
    sta = (cs[idx] - cs[idx - ns]) / ns
    lta = (cs[idx] - cs[lo]) / (idx - lo)[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(lta > 0, sta / lta, 0.0)
    out[first - 1:] = r
    return out


def _longest_constant_run(x: np.ndarray) -> int:
    if x.size < 2:
        return int(x.size)
    change = np.flatnonzero(np.diff(x) != 0)
    bounds = np.concatenate(([-1], change, [x.size - 1]))
    return int(np.diff(bounds).max())


def _runs_at(mask: np.ndarray, min_run: int) -> np.ndarray:
    """Samples of ``mask`` that belong to runs of at least ``min_run`` consecutive True."""
    if not mask.any():
        return mask
    edges = np.diff(np.concatenate(([0], mask.view(np.int8), [0])))
    s = np.flatnonzero(edges == 1)
    e = np.flatnonzero(edges == -1)
    out = np.zeros_like(mask)
    for a, b in zip(s[(e - s) >= min_run], e[(e - s) >= min_run]):
        out[a:b] = True
    return out


def _clipped(x: np.ndarray, lo: float, hi: float, med: float, min_run: int) -> np.ndarray:
    """Flat tops: runs of ``min_run``+ samples exactly at the channel's extreme, far from the median."""
    out = np.zeros(x.shape, bool)
    spread = max(hi - med, med - lo)
    for level in (hi, lo):
        if abs(level - med) < 0.5 * spread:
            continue
        out |= _runs_at(x == level, min_run)
    return out


def _spikes(x: np.ndarray, finite: np.ndarray, k: float, rate: float) -> np.ndarray:
    """Isolated samples farther than ``k`` sigmas from the median of the 5 samples around them.

    Sigma is the larger of the robust spread of the first differences over the window and their
    RMS over the surrounding second (without the 5 samples themselves): band-limited peaks and
    strong shaking are not spikes, a lone outlier in a quiet stretch is.
    """
    n = x.size
    if n < 7:
        return np.zeros(n, bool)
    y = np.where(finite, x, np.median(x[finite]) if finite.any() else 0.0)
    padded = np.concatenate((y[:1], y[:1], y, y[-1:], y[-1:]))
    med5 = np.partition(np.lib.stride_tricks.sliding_window_view(padded, 5), 2, axis=1)[:, 2]
    a = np.abs(y - med5)
    d = np.diff(y)
    sigma = 1.4826 * float(np.median(np.abs(d - np.median(d))))
    d2 = np.concatenate(([0.0], d * d))  # d2[i] = (y[i] - y[i-1])^2
    cs = np.concatenate(([0.0], np.cumsum(d2)))
    half = max(3, int(rate / 2))
    i = np.arange(n)
    lo, hi = np.clip(i - half, 0, n), np.clip(i + half + 1, 0, n)
    ilo, ihi = np.clip(i - 2, 0, n), np.clip(i + 3, 0, n)
    m = (hi - lo) - (ihi - ilo)
    local = np.sqrt(np.maximum(cs[hi] - cs[lo] - (cs[ihi] - cs[ilo]), 0.0) / np.maximum(m, 1))
    scale = np.maximum(sigma, local)
    if not np.any(scale > 0):
        return np.zeros(n, bool)
    big = a > k * scale
    if not big.any():
        return big
    # isolated: neither neighbour is big as well (oscillations are not spikes)
    nb = np.zeros(n, bool)
    nb[1:] |= big[:-1]
    nb[:-1] |= big[1:]
    return big & ~nb & finite


def windows_summary(windows: Iterable[Window]) -> list[dict[str, Any]]:
    """One plain record per window (for JSON outputs and the CLI)."""
    out = []
    for w in windows:
        flags = w.flags
        out.append({
            "window_id": w.window_id,
            "start": iso_utc(w.start_ns),
            "end": iso_utc(w.end_ns),
            "start_ns": int(w.start_ns),
            "end_ns": int(w.end_ns),
            "sample_rate_hz": w.sample_rate_hz,
            "n_samples": w.n_samples,
            "channel_names": list(w.channel_names),
            "channel_status": list(w.channel_status or []),
            "temperature_c": w.temperature_c,
            "is_event": bool(w.is_event),
            "pga_m_s2": float(w.pga_m_s2),
            "input_channel": w.input_channel,
            "flagged_samples": {
                name: {f.name.lower(): int(((flags[:, c] & f) != 0).sum())
                       for f in SampleFlag if f and flags is not None and ((flags[:, c] & f) != 0).any()}
                for c, name in enumerate(w.channel_names)
            } if flags is not None else {},
            "notes": list(w.notes),
        })
    return out
