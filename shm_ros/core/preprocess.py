"""Pre-processing of a window's raw samples before identification (each step can be switched).

Order: channel selection -> offset/trend removal (gravity, drift) -> band-pass (zero-phase
Butterworth, ``scipy.signal.sosfiltfilt``) -> decimation with anti-alias filter
(``scipy.signal.decimate``, zero-phase, in stages of at most 10).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np
import scipy.signal as sig

from shm_ros.core.config import check_choice, option

__all__ = ["Detrend", "PreprocessConfig", "Prepared", "preprocess", "decimate"]

_BAD_STATUS = {"dead", "clipped", "dropped"}


class Detrend(enum.StrEnum):
    NONE = "none"
    CONSTANT = "constant"  # offsets (e.g. gravity)
    LINEAR = "linear"  # offsets and drift


@dataclass
class PreprocessConfig:
    """Switchable pre-processing; the defaults only remove offsets and linear trends."""

    channels: list[str] | None = option(None, "channels to identify from, by name (unset: all usable)")
    detrend: str = option(Detrend.LINEAR.value, "offset/trend removal: none, constant (offsets, e.g. "
                          "gravity) or linear (offsets and drift)", choices=Detrend)
    highpass_hz: float | None = option(None, "band-pass lower corner, Hz (unset: off)")
    lowpass_hz: float | None = option(None, "band-pass upper corner, Hz (unset: off; e.g. 20)")
    filter_order: int = option(8, "Butterworth order of each band edge (zero-phase, so doubled)")
    target_rate_hz: float | None = option(None, "decimate (with anti-alias filter) by the largest "
                                          "integer factor not below this rate, Hz (unset: off)")
    drop_bad_channels: bool = option(True, "drop channels whose status is dead/clipped/dropped or "
                                     "that hold NaN or a constant")

    def validate(self) -> PreprocessConfig:
        check_choice("preprocess", "detrend", self.detrend, Detrend)
        return self


@dataclass
class Prepared:
    data: np.ndarray  # (n_samples, n_channels) float64
    sample_rate_hz: float
    channel_names: list[str]
    notes: list[str] = field(default_factory=list)


def _decimate(x: np.ndarray, factor: int) -> np.ndarray:
    # scipy recommends stages of at most ~13 for its IIR anti-alias filter
    while factor > 1:
        divisors = [q for q in range(min(factor, 10), 1, -1) if factor % q == 0]
        step = divisors[0] if divisors else factor
        x = sig.decimate(x, step, ftype="iir", axis=0, zero_phase=True)
        factor //= step
    return x


def _detrend(x: np.ndarray, linear: bool) -> np.ndarray:
    """Remove each channel's mean and, if ``linear``, its least-squares slope (same result as
    ``scipy.signal.detrend`` without a breakpoint, in one pass over the data)."""
    out = x - x.mean(axis=0)
    if linear and x.shape[0] > 1:
        t = np.arange(x.shape[0], dtype=float)
        t -= t.mean()
        out -= np.outer(t, (t @ out) / (t @ t))
    return out


def _finite_columns(x: np.ndarray) -> np.ndarray:
    """Per column: every sample finite. A finite column sum says so in one pass over the data
    (a NaN or inf makes it NaN or inf); only a sum that is not finite needs the sample check."""
    with np.errstate(over="ignore", invalid="ignore"):
        finite = np.isfinite(x.sum(axis=0))
    if not finite.all():
        finite = np.isfinite(x).all(axis=0)
    return finite


def preprocess(samples: np.ndarray, fs: float, channel_names: list[str],
               config: PreprocessConfig | None = None,
               channel_status: list[str] | None = None) -> Prepared:
    """Apply ``config`` to raw ``samples`` (n, c); returns the data to identify from."""
    cfg = config or PreprocessConfig()
    x = np.asarray(samples, dtype=float)
    if x.ndim != 2 or x.shape[1] != len(channel_names):
        raise ValueError(f"samples of shape {x.shape} do not match {len(channel_names)} channel names")
    if fs <= 0:
        raise ValueError(f"sample rate must be positive, got {fs}")
    notes: list[str] = []
    names = list(channel_names)
    if cfg.channels is not None:
        missing = [c for c in cfg.channels if c not in names]
        if missing:
            raise ValueError(f"preprocess.channels: no channel named {missing} (have {names})")
        idx = [names.index(c) for c in cfg.channels]
    else:
        idx = list(range(len(names)))
    finite = _finite_columns(x)
    if cfg.drop_bad_channels:
        kept = []
        with np.errstate(invalid="ignore"):
            constant = ~(x != x[:1]).any(axis=0)  # a NaN column is dropped as such before this
        for k in idx:
            status = channel_status[k] if channel_status is not None else "ok"
            if status in _BAD_STATUS:
                notes.append(f"channel {names[k]} dropped: status {status}")
            elif not finite[k]:
                notes.append(f"channel {names[k]} dropped: contains NaN/inf samples")
            elif constant[k]:
                notes.append(f"channel {names[k]} dropped: constant (dead)")
            else:
                kept.append(k)
        idx = kept
    if not idx:
        raise ValueError("no usable channel left after channel selection: " + "; ".join(notes))
    if idx != list(range(x.shape[1])) or cfg.detrend == "none":  # detrending makes a new array
        x = x[:, idx]
    names = [names[k] for k in idx]
    if not np.all(finite[idx]):
        raise ValueError("selected channels contain NaN/inf samples (enable drop_bad_channels)")

    cfg.validate()
    if cfg.detrend != "none":
        x = _detrend(x, cfg.detrend == "linear")

    nyq = fs / 2
    lo = cfg.highpass_hz
    hi = cfg.lowpass_hz
    if hi is not None and hi >= nyq:
        notes.append(f"low-pass {hi} Hz at or above Nyquist {nyq} Hz: skipped")
        hi = None
    if lo is not None and lo <= 0:
        lo = None
    if lo is not None and hi is not None:
        if lo >= hi:
            raise ValueError(f"preprocess: highpass_hz {lo} must be below lowpass_hz {hi}")
        sos = sig.butter(cfg.filter_order, [lo, hi], btype="bandpass", fs=fs, output="sos")
    elif hi is not None:
        sos = sig.butter(cfg.filter_order, hi, btype="lowpass", fs=fs, output="sos")
    elif lo is not None:
        sos = sig.butter(cfg.filter_order, lo, btype="highpass", fs=fs, output="sos")
    else:
        sos = None
    if sos is not None:
        x = sig.sosfiltfilt(sos, x, axis=0)

    if cfg.target_rate_hz is not None:
        factor = int(np.floor(fs / cfg.target_rate_hz + 1e-9))
        if factor > 1:
            x = _decimate(x, factor)
            fs = fs / factor
            notes.append(f"decimated by {factor} to {fs:g} Hz")
    return Prepared(np.ascontiguousarray(x), float(fs), names, notes)


def decimate(prep: Prepared, factor: int, why: str = "") -> Prepared:
    """``prep`` decimated by ``factor`` (anti-alias filter as in :func:`preprocess`), with a note."""
    if factor <= 1:
        return prep
    x = _decimate(prep.data, factor)
    fs = prep.sample_rate_hz / factor
    note = f"decimated by {factor} to {fs:g} Hz" + (f" ({why})" if why else "")
    return Prepared(np.ascontiguousarray(x), float(fs), list(prep.channel_names), [*prep.notes, note])
