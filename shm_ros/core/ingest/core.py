"""The ingest core: accelerometer and temperature samples in, checked and aligned windows out.

:class:`IngestCore` is fed array by array (offline readers, importers) or sample by sample (a live
node) and emits finished :class:`~shm_ros.core.types.Window` objects and
:class:`~shm_ros.core.diagnostics.Diagnostic` records. It knows no message type: the adapters
decode messages and hand it stamps (integer ns) and values per topic or block channel. The rules
(grid, snapping, bursts, windows, fault policy) are in ``docs/ingest.md`` and in the modules this
facade drives: ``grid`` (snapping), ``rates`` (the sample rate of each burst), ``segment`` (bursts
and windows), ``span`` (placing and splitting), ``window`` (quality and events of a window).

When is a window final? Offline (``max_latency_s = inf``) the reader calls :meth:`advance` with a
time before which it has fed everything, and :meth:`flush` at the end. Live, a window is cut once
every channel's newest stamp is ``settle_s`` past its end, or once the median channel is
``max_latency_s`` past it (a silent channel then no longer holds it back); :meth:`tick` moves the
stream time on when no data comes.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Sequence

import numpy as np

from shm_ros.core.diagnostics import Diagnostic, Level
from shm_ros.core.ingest.buffers import ChannelBuffer
from shm_ros.core.ingest.channels import ChannelMap
from shm_ros.core.ingest.config import IngestConfig
from shm_ros.core.ingest.diagnostics import DiagnosticLog
from shm_ros.core.ingest.grid import MAX_RATE_HZ, MIN_RATE_HZ, Grid, estimate_rate, fit_clock, follow_clock
from shm_ros.core.ingest.rates import BlockRates, stamps_rate
from shm_ros.core.ingest.results import DroppedSpan, IngestStats
from shm_ros.core.ingest.segment import Bursts
from shm_ros.core.ingest.span import place_span, split_span
from shm_ros.core.ingest.units import unit_factor, units_hint_from_gravity
from shm_ros.core.ingest.window import WindowContext, make_window
from shm_ros.core.types import SampleFlag, Window

_PENDING_MAX = 4096  # per-sample input consolidated into arrays after this many samples
_PENDING_RATE = 256  # ... or this many while the rate is still unknown


MAX_STAMP_NS = (2**31 - 1) * 1_000_000_000  # builtin_interfaces/Time.sec is an int32

class IngestCore:
    """Streaming validation, alignment and windowing.

    Feed with :meth:`add_accel` (arrays of one accelerometer topic) or :meth:`add_accel_sample`,
    :meth:`add_block` and :meth:`add_temperature`; collect finished windows with
    :meth:`pop_windows` and diagnostics with :meth:`pop_diagnostics`; call :meth:`flush` at the end
    of the stream (or :meth:`tick` from a timer so that a burst that has ended is emitted without
    waiting for new data).
    """

    def __init__(self, channel_map: ChannelMap, config: IngestConfig | None = None) -> None:
        self.map = channel_map
        self.config = config or IngestConfig()
        self.channels = channel_map.sensor_ids
        self.n_channels = len(self.channels)
        self._buf = [ChannelBuffer(s) for s in self.channels]
        self._accel_routes = channel_map.imu_routes()
        self._block_routes = channel_map.block_routes()
        self._labels: dict[str, tuple[str, str | None]] = {}  # topic id -> (source, field) from the adapter
        self._pending: dict[str, tuple[list, list, list, list]] = {}  # per-sample input per topic
        self._pending_n = 0
        self._busy = False  # inside a drain or a cut: no nested processing
        self._rate: float | None = self.config.sample_rate_hz  # the newest known rate (None: none yet)
        self._burst_rates: list[float] = []  # the rate of each burst, in order
        self._block_rates = BlockRates()
        self._rate_probe: dict[str, list[int]] = {}
        self._gravity_checked: set[str] = set()
        self._seq = 0
        self._chan_max: list[int | None] = [None] * self.n_channels
        self._due_ns: int | None = None  # process when the stream's final time passes this
        self._committed_ns: int | None = None  # grid time before which everything is emitted
        self._bursts = Bursts(self.config.burst_pause_s * 1e9, int(self.config.check_interval_s * 1e9))
        self._temps_t: list[int] = []
        self._temps_v: list[float] = []
        self._temp_t = np.empty(0, np.int64)
        self._temp_v = np.empty(0, np.float64)
        self._channel_factor: list[float | None] = [None] * self.n_channels  # declared units seen
        self._seen_source: list[str | None] = [None] * self.n_channels  # source that fed it
        self._log = DiagnosticLog(self.config.max_repeats)
        self._window_ctx = WindowContext(self.channels, self.config, self._log, self._src,
                                         self._channel_factor, channel_map.input_sensor)
        self._windows: list[Window] = []
        self.dropped: list[DroppedSpan] = []
        self.stats = IngestStats()

    # ------------------------------------------------------------------ results

    @property
    def sample_rate_hz(self) -> float | None:
        """The rate of the first burst (each window carries its own burst's rate)."""
        return self._burst_rates[0] if self._burst_rates else self._rate

    @property
    def sample_rates_hz(self) -> list[float]:
        """The distinct rates of the bursts so far, in order of first appearance."""
        out: list[float] = []
        for r in self._burst_rates:
            if r not in out:
                out.append(r)
        return out

    @property
    def diagnostic_counts(self) -> Counter[tuple[str, str]]:
        """``(code, source) -> occurrences`` of every diagnostic, also those not recorded."""
        return self._log.counts

    @property
    def diagnostics(self) -> list[Diagnostic]:
        """The diagnostics kept (the newest 10 000 or more; repeats of one code and source beyond
        ``max_repeats`` between two windows are only counted)."""
        return list(self._log.kept)

    def pop_windows(self) -> list[Window]:
        out, self._windows = self._windows, []
        return out

    def pop_diagnostics(self) -> list[Diagnostic]:
        """Diagnostics recorded since the last call (for a node to publish)."""
        return self._log.pop_new()

    # ------------------------------------------------------------------ feeding

    def add_accel(self, topic_id: str, stamps_ns: np.ndarray, xyz: np.ndarray, source: str | None = None,
                  field: str | None = None) -> None:
        """Samples of one accelerometer topic: ``stamps_ns`` (n,), ``xyz`` (n, 3) in m/s^2 (gravity
        included). Diagnostics name the topic ``source`` (default ``accel/<topic_id>``), the
        ``field`` that holds the three axes when the adapter gives one, and the axis:
        ``<source>.<field>.<axis>``. Both are remembered per topic."""
        label = self._label(topic_id, source, field)
        routes = self._accel_routes.get(topic_id)
        if routes is None:
            self._log.add(Level.WARN, "unknown_topic", self._topic(topic_id),
                          "accelerometer topic not in the structure's sensors: ignored", once=True)
            return
        try:
            t = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
            a = np.asarray(xyz, dtype=np.float64)
            if a.shape != (t.size, 3):
                raise ValueError(f"xyz has shape {a.shape}, expected ({t.size}, 3)")
        except (TypeError, ValueError, OverflowError) as exc:
            self._reject(self._topic(topic_id), f"malformed accelerometer samples: {exc}")
            return
        if t.size == 0:
            return
        bad = (t < 0) | (t > MAX_STAMP_NS)
        if bad.any():
            self._reject(self._topic(topic_id), f"{int(bad.sum())} stamp(s) outside 1970-01-01 .. 2038-01-19 "
                         "(what a ROS time holds): not used")
            t, a = t[~bad], a[~bad]
            if t.size == 0:
                return
        self._probe_rate(topic_id, t)
        if topic_id not in self._gravity_checked and t.size >= 64:
            self._check_gravity(topic_id, a, label)
        seq = self._next_seq(t.size)
        for col, axis, sign in routes:
            v = a[:, axis] if sign == 1.0 else a[:, axis] * sign
            self._append(col, t, np.ascontiguousarray(v), seq, f"{label}.{'xyz'[axis]}")
        self._after_add()

    def add_accel_sample(self, topic_id: str, stamp_ns: int, ax: float, ay: float, az: float,
                         source: str | None = None, field: str | None = None) -> None:
        """One sample of an accelerometer topic (m/s^2); consolidated into arrays in batches."""
        pend = self._pending.get(topic_id)
        if pend is None:
            if topic_id not in self._accel_routes:
                self._label(topic_id, source, field)
                self._log.add(Level.WARN, "unknown_topic", self._topic(topic_id),
                              "accelerometer topic not in the structure's sensors: ignored", stamp_ns, once=True)
                return
            self._label(topic_id, source, field)
            pend = self._pending[topic_id] = ([], [], [], [])
        pend[0].append(stamp_ns)
        pend[1].append(ax)
        pend[2].append(ay)
        pend[3].append(az)
        self._pending_n += 1
        if self._pending_n >= _PENDING_MAX or (self._rate is None and self._pending_n >= _PENDING_RATE):
            self._drain_pending()
        elif self._due_ns is not None and stamp_ns > self._due_ns + self._wait_ns:
            self._drain_pending()

    def add_block(self, stamp_ns: int, sample_rate_hz: float, channel_names: Sequence[str],
                  samples: np.ndarray, units: str = "m/s^2", topic: str = "accel_block") -> None:
        """One block of a DAQ: sample k of ``samples`` (n, c) is at ``stamp_ns + k / rate``; ``units``
        is converted to m/s^2 (an unknown unit rejects the block)."""
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
            if not (math.isfinite(rate) and MIN_RATE_HZ <= rate <= MAX_RATE_HZ):
                raise ValueError(f"sample_rate_hz = {rate} (from {MIN_RATE_HZ:g} to at most {MAX_RATE_HZ:g})")
            t0 = int(stamp_ns)
            if not 0 <= t0 <= MAX_STAMP_NS - x.shape[0] * 1e9 / rate:
                raise ValueError(f"stamp {t0} ns is outside 1970-01-01 .. 2038-01-19 (what a ROS time holds)")
        except (TypeError, ValueError, OverflowError) as exc:
            self._reject(f"{topic}", f"malformed AccelBlock: {exc}", None)
            return
        factor = unit_factor(units or "")
        if factor is None:
            self._reject(f"{topic}.units", f"unknown units {units!r} (m/s^2, g, cm/s^2 or mm/s^2): "
                         "block rejected", t0)
            return
        fixed = self.config.sample_rate_hz
        if fixed is not None and abs(rate - fixed) > 1e-6 * fixed:
            self._reject(f"{topic}.sample_rate_hz", f"block at {rate:g} Hz, grid at {fixed:g} Hz "
                         "(sample_rate_hz): not resampled, block rejected", t0)
            return
        pause_ns = self.config.burst_pause_s * 1e9
        if not self._block_rates.accepts(t0, rate, self._newest_stamp(), pause_ns):
            self._reject(f"{topic}.sample_rate_hz", f"block at {rate:g} Hz inside a burst at "
                         f"{self._block_rates.last_rate:g} Hz: not resampled, block rejected", t0)
            return
        if self._rate is None:
            self._rate = rate
            self._log.add(Level.OK, "sample_rate", f"{topic}.sample_rate_hz", f"grid rate {rate:g} Hz", t0)
        n = x.shape[0]
        if n == 0:
            return
        self._block_rates.add(t0, t0 + int(round((n - 1) * 1e9 / rate)), rate)
        t = t0 + np.round(np.arange(n) * (1e9 / rate)).astype(np.int64)
        seq = self._next_seq(n)
        # what depends on the block's stamps or on all its values is found once for the block: its
        # stamps ascend, by steps of one period (no clock jump inside), and which of its columns
        # hold an implausible value (|x * factor * sign| = |x| |factor| exactly)
        steady = float(1e9 / rate) + 1.0 <= self.config.clock_jump_s * 1e9  # steps are rounded to 1 ns
        flagged = self._implausible_columns(x, factor)
        for j, name in enumerate(names):
            routes = self._block_routes.get(name)
            if routes is None:
                self._log.add(Level.WARN, "unknown_channel", f"{topic}.channel_names[{name}]",
                              "channel not in the structure's sensors: ignored", t0, once=True)
                continue
            for col, sign in routes:
                v = x[:, j] * factor if factor != 1.0 else x[:, j].copy()
                if sign != 1.0:
                    v = v * sign
                if self._channel_factor[col] is None:
                    self._channel_factor[col] = factor
                self._append(col, t, v, seq, f"{topic}.samples[{name}]",
                             steady=steady, plausible=not flagged[j])
        self._after_add()

    def add_blocks(self, stamps_ns: Sequence[int], sample_rate_hz: float, channel_names: Sequence[str],
                   samples: Sequence[np.ndarray], units: str = "m/s^2", topic: str = "accel_block") -> None:
        """Blocks of one topic with one rate, channel list and units, in order (a recorded run):
        the same windows and diagnostics as :meth:`add_block` on each in turn. Each stretch of
        blocks that start exactly where the one before ends (a whole number of ns per sample) is
        fed as one block when every channel is known and no value is implausible."""
        names = [str(c) for c in channel_names]
        period = self._block_period(sample_rate_hz, names, units)
        i, n = 0, len(samples)
        while i < n:
            j, t_next = i, int(stamps_ns[i])
            xs: list[np.ndarray] = []
            while period and j < n and int(stamps_ns[j]) == t_next:
                x = np.asarray(samples[j], dtype=np.float64)
                if x.ndim != 1 or x.size == 0 or x.size % len(names):
                    break
                xs.append(x)
                t_next += x.size // len(names) * period
                j += 1
            merged = self._merged(xs, names, units, int(stamps_ns[i]), float(sample_rate_hz)) if len(xs) > 1 else None
            if merged is None:
                j = i + 1
                self.add_block(stamps_ns[i], sample_rate_hz, names, samples[i], units, topic)
            else:
                self.add_block(int(stamps_ns[i]), sample_rate_hz, names, merged, units, topic)
            i = j

    def _block_period(self, sample_rate_hz: float, names: list[str], units: str) -> int:
        """The sample period (ns) of blocks that :meth:`add_blocks` may join; 0: feed one by one."""
        rate = float(sample_rate_hz)
        fixed = self.config.sample_rate_hz
        if not names or any(c not in self._block_routes for c in names) or unit_factor(units or "") is None:
            return 0
        if not (math.isfinite(rate) and MIN_RATE_HZ <= rate <= MAX_RATE_HZ) or not (1e9 / rate).is_integer() or (
                fixed is not None and abs(rate - fixed) > 1e-6 * fixed):
            return 0
        return int(1e9 / rate)

    def _merged(self, xs: list[np.ndarray], names: list[str], units: str, t0: int, rate: float) -> np.ndarray | None:
        """Contiguous blocks' samples as one (n, c) array; None when joining them could change a
        diagnostic (an implausible value: one diagnostic per block; a rate the burst refuses)."""
        if not self._block_rates.accepts(t0, rate, self._newest_stamp(), self.config.burst_pause_s * 1e9):
            return None
        merged = np.concatenate(xs).reshape(-1, len(names))
        if self._implausible_columns(merged, unit_factor(units or "") or 1.0).any():
            return None
        return merged

    def _implausible_columns(self, x: np.ndarray, factor: float) -> np.ndarray:
        """Which columns of ``x`` (in units scaled to m/s^2 by ``factor``) hold an implausible value."""
        return np.any((np.abs(x) * abs(factor) > self.config.implausible_m_s2) & np.isfinite(x), axis=0)

    def add_temperature(self, sensor_id: str, stamp_ns: int, value_c: float, source: str | None = None) -> None:
        """One temperature sample (degrees C); a window's temperature is the mean of those inside it.
        ``source`` names it in diagnostics (default ``temperature/<sensor_id>``)."""
        source = source or f"temperature/{sensor_id}"
        try:
            t, v = int(stamp_ns), float(value_c)
            if not 0 <= t <= MAX_STAMP_NS:
                raise ValueError(f"stamp {t} ns is outside 1970-01-01 .. 2038-01-19")
        except (TypeError, ValueError, OverflowError) as exc:
            self._reject(source, f"malformed temperature: {exc}")
            return
        if not math.isfinite(v):
            self._log.add(Level.WARN, "nan", source, f"non-finite temperature {v}: not used in window means", t)
            return
        if self._committed_ns is not None and t < self._committed_ns:
            self._log.add(Level.OK, "late_temperature", source,
                          "temperature sample older than the last emitted window: not used", t)
            return
        self._temps_t.append(t)
        self._temps_v.append(v)

    def report_error(self, source: str, message: str, level: Level | int = Level.ERROR,
                     code: str = "input_error") -> None:
        """Record a fault found outside the core (e.g. a bag that cannot be read further)."""
        self._log.add(Level(level), code, source, message)

    # ------------------------------------------------------------------ time

    def tick(self, now_ns: int) -> None:
        """Time has reached ``now_ns`` (stamp clock): close what cannot change any more."""
        if self.config.streaming:
            self.advance(int(now_ns) - self._latency_ns)

    def advance(self, final_ns: int) -> None:
        """Every sample stamped before ``final_ns`` has been fed: cut what that completes.

        Readers that know their order (a bag read in time order) call this with
        ``max_latency_s=inf``; a live stream relies on ``settle_s``/``max_latency_s`` instead.
        """
        if self._rate is None:
            self._drain_pending()
            if self._rate is None:
                return
        maxima = [m for m in self._chan_max if m is not None]
        stopped = bool(maxima) and final_ns - max(maxima) > self.config.burst_pause_s * 1e9
        if self._due_ns is None or int(final_ns) >= self._due_ns or (
                stopped and any(b.size for b in self._buf)):
            self._process(int(final_ns))

    def flush(self) -> list[Window]:
        """End of stream: cut everything still buffered; returns (and pops) all finished windows."""
        self._drain_pending()
        self._process(None)
        self._temp_t = np.empty(0, np.int64)
        self._temp_v = np.empty(0, np.float64)
        return self.pop_windows()

    @property
    def _wait_ns(self) -> int:
        """Stamp time past a due point after which buffered samples are worth a look."""
        settle = self.config.settle_s
        return self._latency_ns if settle is None else min(self._latency_ns, int(settle * 1e9))

    @property
    def _latency_ns(self) -> int:
        return int(self.config.max_latency_s * 1e9) if self.config.streaming else 2**62

    def _final_ns(self) -> int | None:
        """Stream time before which the buffered data is final (None: wait for the end)."""
        maxima = [m for m in self._chan_max if m is not None]
        if not maxima or not self.config.streaming:
            return None
        # the median channel, so that one channel with a clock jump forward cannot close windows
        final = int(np.median(maxima)) - self._latency_ns
        settle = self.config.settle_s
        if settle is not None and len(maxima) == self.n_channels:
            # every expected channel has reached ``end + settle``: nothing earlier can still come
            # (each channel's own stamps arrive in order); a silent or lagging channel holds this
            # back, and then only the median rule above closes the window
            final = max(final, min(maxima) - int(settle * 1e9))
        return final

    # ------------------------------------------------------------------ internals: feeding

    def _label(self, topic_id: str, source: str | None = None, field: str | None = None) -> str:
        """``<source>[.<field>]`` of a topic (what its axes are appended to); remembers the names."""
        if source is not None or field is not None:
            old = self._labels.get(topic_id, (f"accel/{topic_id}", None))
            self._labels[topic_id] = (source or old[0], field or old[1])
        topic, fld = self._labels.get(topic_id, (f"accel/{topic_id}", None))
        return topic if fld is None else f"{topic}.{fld}"

    def _topic(self, topic_id: str) -> str:
        return self._labels.get(topic_id, (f"accel/{topic_id}", None))[0]

    def _src(self, c: int) -> str:
        """Diagnostic source of output channel ``c``: the input that fed it, or what it reads."""
        seen = self._seen_source[c]
        if seen is not None:
            return f"{seen} (sensor {self.channels[c]})"
        s = self.map.sources[c]
        out = []
        if s.imu_topic is not None:
            out.append(f"{self._label(s.imu_topic)}.{s.axis}")
        if s.block_channel is not None:
            out.append(f"accel_block.samples[{s.block_channel}]")
        return " | ".join(out) + f" (sensor {s.sensor_id})"

    def _reject(self, source: str, message: str, stamp_ns: int | None = None) -> None:
        self.stats.messages_rejected += 1
        self._log.add(Level.ERROR, "rejected", source, message, stamp_ns)

    def _next_seq(self, n: int) -> np.ndarray:
        s = np.arange(self._seq, self._seq + n, dtype=np.int64)
        self._seq += n
        return s

    def _drain_pending(self) -> None:
        if not self._pending_n:
            return
        pending, self._pending = self._pending, {}
        self._pending_n = 0
        busy, self._busy = self._busy, True  # every topic in first, then one look at the windows
        try:
            for topic_id, (ts, xs, ys, zs) in pending.items():
                self._feed_pending(topic_id, ts, xs, ys, zs)
        finally:
            self._busy = busy
        self._after_add()

    def _feed_pending(self, topic_id: str, ts: list, xs: list, ys: list, zs: list) -> None:
        if not ts:
            return
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
                    self._reject(f"{self._topic(topic_id)} (stamp)", f"bad stamp {s!r}")
            t = np.asarray([ts[i] for i in good], dtype=np.int64)
            xs, ys, zs = ([v[i] for i in good] for v in (xs, ys, zs))
        try:
            xyz = np.column_stack((np.asarray(xs, np.float64), np.asarray(ys, np.float64),
                                   np.asarray(zs, np.float64)))
        except (TypeError, ValueError) as exc:
            self._reject(self._topic(topic_id), f"non-numeric values: {exc}")
            return
        self.add_accel(topic_id, t, xyz)

    def _check_gravity(self, topic_id: str, a: np.ndarray, label: str) -> None:
        """An accelerometer at rest reads |a| = g on its three axes together: ~1 means g, ~981 cm/s^2."""
        self._gravity_checked.add(topic_id)
        with np.errstate(over="ignore", invalid="ignore"):  # implausible samples are reported elsewhere
            mag = float(np.nanmedian(np.sqrt(np.sum(a * a, axis=1))))
        guess, implausible = units_hint_from_gravity(mag)
        if guess:
            self._log.add(Level.WARN, "units", label,
                          f"|a| of the three axes = {mag:.4g} at rest looks like {guess}, not m/s^2 "
                          "(m/s^2 with gravity expected): values NOT rescaled")
        elif implausible:
            self._log.add(Level.WARN, "units", label,
                          f"|a| of the three axes = {mag:.4g} m/s^2 is implausible for a structure "
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
                self._log.add(Level.OK, "sample_rate", f"{self._topic(topic_id)} (stamps)",
                              f"grid rate {rate:g} Hz (fitted to the stamps)", int(t[0]))

    def _append(self, col: int, t: np.ndarray, v: np.ndarray, seq: np.ndarray, source: str,
                steady: bool = False, plausible: bool = False) -> None:
        """Check and buffer one channel's samples. ``steady``: the stamps ascend by steps within
        the clock-jump limit (a DAQ block); ``plausible``: no value is beyond the implausible limit
        (the checks that would find nothing are then left out)."""
        buf = self._buf[col]
        self._seen_source[col] = source
        self.stats.samples_in += int(t.size)
        if self._committed_ns is not None and not (steady and t[0] >= self._committed_ns):
            late = t < self._committed_ns
            if late.any():
                n = int(late.sum())
                self.stats.samples_not_windowed["late"] += n
                self._log.add(Level.WARN, "late_sample", source,
                              f"{n} sample(s) stamped before the last emitted window (clock jump "
                              "backwards or late delivery): rejected", int(t[late][0]), n)
                keep = ~late
                t, v, seq = t[keep], v[keep], seq[keep]
                if t.size == 0:
                    return
        self._check_values(col, t, v, source, steady, plausible)
        n_ooo = buf.append(t, v, seq, ascending=steady)
        if n_ooo:
            self._log.add(Level.WARN, "out_of_order", source,
                          f"{n_ooo} stamp(s) earlier than a previous stamp: placed by stamp, flagged "
                          "OUT_OF_ORDER", int(t[0]), n_ooo)
        tmax = int(t[-1] if steady else t.max())
        cm = self._chan_max[col]
        self._chan_max[col] = tmax if cm is None else max(cm, tmax)

    def _check_values(self, col: int, t: np.ndarray, v: np.ndarray, source: str, steady: bool = False,
                      plausible: bool = False) -> None:
        """Implausible magnitudes become NaN (flagged NAN in their window) and clock jumps - forward by
        more than ``clock_jump_s`` or any step back - are reported; both as diagnostics naming the source.
        ``steady`` and ``plausible``: see :meth:`_append`."""
        lim = self.config.implausible_m_s2
        jump_ns = self.config.clock_jump_s * 1e9
        prev = self._chan_max[col]
        if plausible and steady and (prev is None or 0 <= t[0] - prev <= jump_ns):
            return
        bad = np.abs(v) > lim
        bad &= np.isfinite(v)  # +-inf is flagged NAN like a NaN
        if bad.any():
            n = int(bad.sum())
            worst = float(np.max(np.abs(v[bad])))
            self.stats.implausible += n
            self._log.add(Level.WARN, "implausible", source,
                          f"{n} sample(s) beyond {lim:g} m/s^2 (up to {worst:.3g}): set to NaN",
                          int(t[bad][0]), n)
            v[bad] = np.nan
        steps = np.diff(t) if prev is None else np.diff(t, prepend=prev)
        if steps.size and (steps.max() > jump_ns or steps.min() < 0):
            k = int(np.argmax(steps > jump_ns)) if steps.max() > jump_ns else int(np.argmax(steps < 0))
            at = int(t[k + 1] if prev is None else t[k])
            step_s = float(steps[k]) / 1e9
            # a step back is a clock fault; a step forward may be a long pause between records
            # (an event catalogue) unless it lands in the future
            future = at > time.time_ns() + jump_ns
            level = Level.WARN if step_s < 0 or future else Level.OK
            what = "back" if step_s < 0 else "forward" + (" into the future" if future else
                                                          " (a long pause, or the clock)")
            self._log.add(level, "clock_jump", source, f"stamps jump {what} by {abs(step_s):.6g} s", at)

    def _newest_stamp(self) -> int | None:
        maxima = [m for m in self._chan_max if m is not None]
        return max(maxima) if maxima else None

    def _after_add(self) -> None:
        if self._rate is None or self._busy:
            return
        final = self._final_ns()
        if final is not None and (self._due_ns is None or final >= self._due_ns):
            self._process(final)

    # ------------------------------------------------------------------ internals: cutting

    def _process(self, final_ns: int | None) -> None:
        """Cut every window whose data is final (``final_ns`` None = end of stream)."""
        busy, self._busy = self._busy, True
        try:
            self._process_now(final_ns)
        finally:
            self._busy = busy

    def _process_now(self, final_ns: int | None) -> None:
        self._drain_pending()
        if self._rate is None:
            buffered = sum(b.size for b in self._buf)
            if final_ns is None and buffered:
                self._log.add(Level.ERROR, "no_rate", "accel", "too few samples to know the sample rate: "
                              "nothing windowed (set sample_rate_hz)")
                self.stats.samples_not_windowed["no_rate"] += buffered
                self._buf = [ChannelBuffer(s) for s in self.channels]
            return
        for b in self._buf:
            b.consolidate()
        if self._temps_t:
            self._temp_t = np.concatenate((self._temp_t, np.asarray(self._temps_t, np.int64)))
            self._temp_v = np.concatenate((self._temp_v, np.asarray(self._temps_v, np.float64)))
            self._temps_t, self._temps_v = [], []
        self._due_ns = self._bursts.process(self._buf, final_ns, self._cut, self._on_burst)
        if self._committed_ns is not None:
            self._block_rates.prune(self._committed_ns)
            if self._temp_t.size:
                keep = self._temp_t >= self._committed_ns
                self._temp_t, self._temp_v = self._temp_t[keep], self._temp_v[keep]

    def _on_burst(self, origin: int, final_ns: int | None) -> tuple[float, int] | None:
        """A burst starts at ``origin``: its rate (Hz) and window length (grid rows); None: wait
        for more of its stamps."""
        rate, how = self.config.sample_rate_hz, "sample_rate_hz"
        if rate is None:
            rate, how = self._block_rates.rate_at(origin), "its AccelBlocks' rate"
        if rate is None:
            rate, decided = stamps_rate(self._buf, origin, final_ns, self.config.burst_pause_s * 1e9,
                                        self.config.rate_tolerance)
            how = "fitted to its stamps"
            if rate is None and not decided:
                return None
            prev = self._burst_rates[-1] if self._burst_rates else self._rate
            if rate is None:  # too few stamps to tell (the burst is too short to be a window anyway)
                assert prev is not None  # (nothing is processed before a first rate is known)
                rate, how = prev, "too few stamps to fit: the previous burst's rate"
            elif prev is not None and abs(rate - prev) <= self.config.rate_tolerance * prev:
                rate = prev  # the same clock as before: keep its rate exactly
        prev = self._burst_rates[-1] if self._burst_rates else None
        self._burst_rates.append(rate)
        self._rate = rate
        self._log.add(Level.OK, "burst", "accel", f"burst starts ({rate:g} Hz, {how})", origin)
        if prev is not None and rate != prev:
            self._log.add(Level.OK, "sample_rate", "accel",
                          f"burst at {rate:g} Hz, the previous one at {prev:g} Hz: its windows are on its "
                          "own grid at its own rate (nothing resampled)", origin)
        return rate, max(1, int(round(self.config.window_s * rate)))

    def _track(self, grid: Grid, k0: int, k1: int) -> None:
        """Follow the stamps' clock over grid rows [k0, k1): re-anchor the grid from k0 on when it
        drifts (see :func:`~shm_ros.core.ingest.grid.follow_clock`). Nothing is resampled."""
        P = grid.period
        lo, hi = grid.edge(k0), grid.edge(k1)
        ts = np.concatenate([b.between(lo, hi) for b in self._buf])
        if ts.size > 100_000:  # a fit needs no more; keeps a 10-minute window cheap
            ts = ts[:: int(math.ceil(ts.size / 100_000))]
        ts = np.sort(ts)
        t0 = grid.time(k0)
        fit = fit_clock(ts, t0, P, k1 - k0)
        if fit is None:
            return
        moved = follow_clock(fit, t0, P, k1 - k0, self.config.rate_tolerance)
        if moved is not None:
            grid.anchor_t, grid.anchor_k, grid.period = moved[0], k0, moved[1]
            self._log.add(Level.OK, "clock_drift", "accel",
                          f"stamps run at {1e9 / fit.period:.7g} Hz, {fit.offset / 1e6:.3g} ms off the grid "
                          f"(grid was {1e9 / P:.7g} Hz): the grid follows the stamps' clock from here", t0)

    def _cut(self, k0: int, k1: int, why: str | None, last_stamp: int | None) -> None:
        """Place the samples of grid rows [k0, k1) and emit the window(s) they make (``last_stamp``:
        the burst's last stamp when it ends here)."""
        grid, rate = self._bursts.grid, self._bursts.rate
        assert grid is not None
        if k1 <= k0:
            return
        self._track(grid, k0, k1)
        if last_stamp is not None:
            k1 = max(k0 + 1, grid.slot(last_stamp) + 1)  # on the (possibly re-anchored) grid
        span = place_span(self._buf, grid, k0, k1, rate, self.config, self._log, self.stats,
                          self._src, self.channels)
        self._committed_ns = grid.edge(k1)
        # a burst that ends inside its first window is shorter than a window: one window of its own
        whole_burst = k0 == 0 and why is not None
        dropped, pieces = split_span(span, grid, self._bursts.window_len, rate, why, self.config, self._log,
                                     self.stats, self._src, self.dropped, whole_burst=whole_burst)
        for p in pieces:
            w = make_window(self._window_ctx, p.start_ns, span.vals[p.rows], span.flags[p.rows], dropped,
                            p.notes, 1e9 / grid.period, rate, (self._temp_t, self._temp_v))
            self.stats.windows += 1
            self._log.window_emitted()
            flags = w.flags if w.flags is not None else np.zeros(w.samples.shape, np.uint8)
            self.stats.samples_windowed += w.samples.size - int(((flags & SampleFlag.MISSING) != 0).sum())
            self._windows.append(w)
