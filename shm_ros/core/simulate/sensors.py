"""What a real accelerometer adds to the structure's motion, and what goes wrong with recordings.

:class:`SensorModel` - per-sensor gain error, static offset, gravity on the vertical axis (REP-145),
white noise, 24-bit-like quantisation and the range limit (clipping at +-2 g by default).

:class:`FaultSpec` / :func:`apply_faults` - dropouts, spikes, NaN stretches, a dead or clipped channel,
clock jumps and duplicated stamps, applied to a :class:`Recording` and listed for ``truth.json``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

GRAVITY = 9.80665
FAULT_KINDS = ("dropout", "spike", "nan", "dead", "clipped", "clock_jump", "duplicate")
AXES = ("x", "y", "z")


@dataclass
class SensorModel:
    """Measurement chain of one accelerometer; ``axis`` is the IMU axis that carries the signal."""

    sensor_id: str
    axis: str  # "x" | "y" | "z"
    gain: float = 1.0
    offsets: tuple[float, float, float] = (0.0, 0.0, 0.0)  # static offsets of x, y, z (gravity excluded)
    gravity_axis: str = "z"
    noise_rms: float = 1e-4  # m/s^2 per sample
    lsb: float = 2.0 ** -19  # quantisation step, m/s^2 (about 24 bits over +-2 g)
    full_scale: float = 2.0 * GRAVITY
    # what the signal axis reads of a unit acceleration along x, y, z of the structure's frame
    # (z up; None: exactly ``frame_axis``); see :meth:`draw`
    sensitivity: tuple[float, float, float] | None = None
    frame_axis: str = "z"  # the structure axis the sensor measures (x, y or z = vertical)
    misalignment_deg: float = 0.0
    cross_axis: tuple[float, float] = (0.0, 0.0)  # sensitivity to the two other axes, beyond misalignment

    @staticmethod
    def draw(rng: np.random.Generator, sensor_id: str, axis: str, noise_rms: float = 1e-4,
             gain_std: float = 0.01, offset_std: float = 0.02, imperfect: bool = False,
             frame_axis: str | None = None) -> SensorModel:
        """A sensor with a drawn gain and offsets; ``imperfect`` adds what a data sheet allows of a
        real MEMS/force-balance accelerometer mounted by hand: gain error 1-3 %, misalignment 0.5-2
        degrees (towards a random direction) and cross-axis sensitivity 1-3 %."""
        gain = float(1.0 + gain_std * rng.standard_normal())
        ox, oy, oz = (float(v) for v in offset_std * rng.standard_normal(3))
        out = SensorModel(sensor_id=sensor_id, axis=axis, gain=gain, offsets=(ox, oy, oz), noise_rms=noise_rms,
                          frame_axis=frame_axis or axis)
        if imperfect:
            out.gain = float(1.0 + rng.choice([-1.0, 1.0]) * rng.uniform(0.01, 0.03))
            delta = np.deg2rad(rng.uniform(0.5, 2.0))
            azimuth = rng.uniform(0.0, 2 * np.pi)
            cross_dir = rng.uniform(0.0, 2 * np.pi)
            cross = rng.uniform(0.01, 0.03) * np.array([np.cos(cross_dir), np.sin(cross_dir)])
            i = AXES.index(out.frame_axis)
            others = [j for j in range(3) if j != i]
            sens = np.zeros(3)
            sens[i] = np.cos(delta)
            sens[others] = np.sin(delta) * np.array([np.cos(azimuth), np.sin(azimuth)]) + cross
            out.sensitivity = (float(sens[0]), float(sens[1]), float(sens[2]))
            out.misalignment_deg = float(np.rad2deg(delta))
            out.cross_axis = (float(cross[0]), float(cross[1]))
        return out

    def static(self, axis: str) -> float:
        """Static reading of ``axis``: its offset plus gravity on the vertical axis (for the signal
        axis of a misaligned sensor: the share of gravity its sensing direction sees)."""
        i = AXES.index(axis)
        if axis == self.axis and self.sensitivity is not None:
            return self.offsets[i] + GRAVITY * self.sensitivity[2]  # gravity is along the structure's z
        return self.offsets[i] + (GRAVITY if axis == self.gravity_axis else 0.0)

    def measure(self, rng: np.random.Generator, accel: np.ndarray) -> np.ndarray:
        """Reading of the signal axis for true acceleration ``accel``: (n,) along the measured
        direction, or (n, 3) along x, y, z of the structure (read through :attr:`sensitivity`), m/s^2."""
        accel = np.asarray(accel, dtype=float)
        if accel.ndim == 2:
            s = np.eye(3)[AXES.index(self.frame_axis)] if self.sensitivity is None else np.asarray(self.sensitivity)
            accel = accel @ s
        y = self.gain * accel + self.static(self.axis) + self.noise_rms * rng.standard_normal(accel.shape)
        return self.quantise(y)

    def idle_axes(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """(n, 3) readings of all axes with no motion (the signal axis is overwritten by the caller)."""
        out = np.empty((n, 3))
        for i, ax in enumerate(AXES):
            out[:, i] = self.static(ax) + self.noise_rms * rng.standard_normal(n)
        return self.quantise(out)

    def quantise(self, y: np.ndarray) -> np.ndarray:
        return np.clip(np.round(y / self.lsb) * self.lsb, -self.full_scale, self.full_scale)


@dataclass
class Recording:
    """Samples of one window as they reach the bag, before faults mangle stamps and values.

    ``values`` (n, n_ch): the signal axis of each sensor; ``idle`` (n, n_ch, 3) or None: all three
    IMU axes (per-sample ``Imu`` output only). Faults edit ``values``/``idle`` and fill ``keep``
    (sample written?), ``shift_ns`` (added to the stamp) and ``repeat`` (extra copies written).
    """

    sensor_ids: list[str]
    axes: list[str]
    stamps_ns: np.ndarray  # (n,) int64 sample grid
    values: np.ndarray
    idle: np.ndarray | None = None
    keep: np.ndarray | None = None
    shift_ns: np.ndarray | None = None
    repeat: np.ndarray | None = None

    @property
    def n(self) -> int:
        return int(self.stamps_ns.size)

    def _masks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``keep``, ``shift_ns`` and ``repeat``, created (no fault yet) on first use."""
        shape = self.values.shape
        if self.keep is None:
            self.keep = np.ones(shape, bool)
        if self.shift_ns is None:
            self.shift_ns = np.zeros(shape, np.int64)
        if self.repeat is None:
            self.repeat = np.zeros(shape, np.uint8)
        return self.keep, self.shift_ns, self.repeat

    def imu_xyz(self, c: int) -> np.ndarray:
        """(n, 3) IMU readings of channel ``c`` (signal axis from ``values``)."""
        xyz = self.idle[:, c, :].copy() if self.idle is not None else np.zeros((self.n, 3))
        xyz[:, AXES.index(self.axes[c])] = self.values[:, c]
        return xyz


@dataclass
class FaultSpec:
    """One fault: ``kind`` in FAULT_KINDS, in window ``window`` (index), on ``sensor`` (None: the
    scenario picks one), starting ``at_s`` into the window, lasting ``duration_s``; ``value`` is the
    spike height (m/s^2), the clock jump (s, may be negative) or the clip level (fraction of the
    channel's peak dynamic amplitude), and ``count`` the number of spikes or duplicated stamps."""

    kind: str
    window: int = 0
    sensor: str | None = None
    at_s: float = 30.0
    duration_s: float = 5.0
    value: float | None = None
    count: int = 5

    def __post_init__(self) -> None:
        if self.kind not in FAULT_KINDS:
            raise ValueError(f"unknown fault {self.kind!r} (known: {', '.join(FAULT_KINDS)})")


def parse_faults(text: str, default_sensor: str | None = None) -> list[FaultSpec]:
    """``"spike@2:s3,dead,clock_jump@0"`` -> faults; ``kind[@window][:sensor]`` separated by commas."""
    out = []
    for item in [t.strip() for t in text.split(",") if t.strip()]:
        sensor = default_sensor
        if ":" in item:
            item, sensor = item.split(":", 1)
        window = 0
        if "@" in item:
            item, w = item.split("@", 1)
            try:
                window = int(w)
            except ValueError:
                raise ValueError(f"--faults: bad window index {w!r} in {item}@{w} (an integer)") from None
        out.append(FaultSpec(kind=item.strip(), window=window, sensor=sensor))
    return out


def apply_faults(rec: Recording, faults: list[FaultSpec], fs: float, rng: np.random.Generator,
                 block_level: bool) -> list[dict]:
    """Apply ``faults`` (already filtered to this window) to ``rec``; return what was done.

    With ``block_level`` (``AccelBlock`` output) dropouts, clock jumps and duplicates hit every channel
    of the acquisition unit at once; value faults (spike, nan, dead, clipped) stay on their channel.
    """
    done = []
    n = rec.n
    for f in faults:
        c = rec.sensor_ids.index(f.sensor) if f.sensor in rec.sensor_ids else len(rec.sensor_ids) // 2
        sid = rec.sensor_ids[c]
        k0 = int(round(f.at_s * fs))
        if not 0 <= k0 < n:  # a start beyond a short window: a third of the way in
            k0 = n // 3
        k1 = int(np.clip(k0 + max(1, round(f.duration_s * fs)), k0 + 1, n))
        cols = slice(None) if block_level else slice(c, c + 1)
        keep, shift_ns, repeat = rec._masks()
        entry: dict = {"kind": f.kind, "window": f.window, "sensor": sid if not (
            block_level and f.kind in ("dropout", "clock_jump", "duplicate")) else "*",
            "start_ns": int(rec.stamps_ns[k0])}
        if f.kind == "dropout":
            keep[k0:k1, cols] = False
            entry["end_ns"] = int(rec.stamps_ns[k1 - 1]) + int(round(1e9 / fs))
            entry["n_samples"] = k1 - k0
        elif f.kind == "spike":
            height = f.value if f.value is not None else 5.0
            ks = np.sort(rng.choice(np.arange(k0, n), size=min(f.count, n - k0), replace=False))
            signs = np.where(rng.random(ks.size) < 0.5, -1.0, 1.0)
            rec.values[ks, c] += signs * height
            entry["stamps_ns"] = [int(rec.stamps_ns[k]) for k in ks]
            entry["height"] = height
        elif f.kind == "nan":
            rec.values[k0:k1, c] = np.nan
            entry["end_ns"] = int(rec.stamps_ns[k1 - 1]) + int(round(1e9 / fs))
        elif f.kind == "dead":
            rec.values[:, c] = rec.values[0, c] if f.value is None else f.value
            if rec.idle is not None:
                rec.idle[:, c, :] = rec.idle[0, c, :]
            entry["start_ns"] = int(rec.stamps_ns[0])
            entry["value"] = float(rec.values[0, c])
        elif f.kind == "clipped":
            x = rec.values[:, c]
            centre = float(np.median(x))
            level = (f.value if f.value is not None else 0.3) * float(np.max(np.abs(x - centre)))
            rec.values[:, c] = np.clip(x, centre - level, centre + level)
            entry["start_ns"] = int(rec.stamps_ns[0])
            entry["clip_level_m_s2"] = level
            entry["fraction_clipped"] = float(np.mean(np.abs(x - centre) > level))
        elif f.kind == "clock_jump":
            jump = f.value if f.value is not None else 0.25
            shift_ns[k0:, cols] += int(round(jump * 1e9))
            entry["jump_s"] = jump
        elif f.kind == "duplicate":
            ks = np.sort(rng.choice(np.arange(k0, n), size=min(f.count, n - k0), replace=False))
            repeat[ks, cols] += 1
            entry["stamps_ns"] = [int(rec.stamps_ns[k]) for k in ks]
        done.append(entry)
    return done
