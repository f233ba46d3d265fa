"""Band of interest, decimation and block rows chosen from the problem (docs/identify.md).

SSI resolves a mode only when its Hankel matrix spans enough of the mode's period: ``i`` block
rows at the rate ``fs`` cover ``i / fs`` seconds, and the default 20 rows at 100 Hz (0.2 s) hold
a tenth of the period of a 0.5 Hz mode, whose poles then scatter between the forward and
backward estimates and across orders. Decimating to the band of the modes of interest and
sizing the block rows to a few periods of the lowest one fixes both, at any sample rate:

* the **band** comes from the structure's nominal model (its lowest ``modes`` frequencies) when
  there is one, else from the spectrum of the outputs (the first singular value of the spectral
  matrix, Welch): the band holding its prominent peaks;
* the **decimation factor** is the largest integer that keeps the band's top, with a margin,
  below the anti-alias filter's pass band (``scipy.signal.decimate`` passes up to 0.4 fs);
* the **block rows** make ``i / fs_decimated`` cover ``periods`` periods of the lowest mode of
  interest, at least the order-based default, at most ``max_block_rows``.

Every choice carries its reason (:meth:`BandChoice.describe`, :meth:`BandChoice.to_dict`).
"""

from __future__ import annotations

import enum
import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import scipy.fft as sp_fft
import scipy.signal as sig

__all__ = ["BandSource", "BandChoice", "band_from_model", "band_from_singular_spectrum", "band_from_spectrum",
           "band_frequencies", "choose_resolution", "first_singular_spectrum", "nominal_frequencies"]

# decimate's IIR anti-alias filter (Chebyshev I, order 8) cuts at 0.8 x the new Nyquist rate,
# i.e. 0.4 fs; the band's top is kept below 0.36 fs so it sits inside the flat part
PASS_FRACTION = 0.36


class BandSource(enum.StrEnum):
    AUTO = "auto"  # the nominal model when the structure gives one, else the spectrum
    MODEL = "model"
    SPECTRUM = "spectrum"
    OFF = "off"  # no automatic band: no decimation, order-based block rows


@dataclass
class BandChoice:
    """What the automatic band chose and why (``source``: model, spectrum, options or none)."""

    source: str
    low_hz: float | None  # lowest mode of interest
    high_hz: float | None  # top of the band (highest mode of interest times the margin)
    decimation: int  # 1: none
    sample_rate_hz: float  # rate the identification runs at
    block_rows: int
    reasons: list[str]

    def to_dict(self) -> dict:
        return asdict(self)

    def describe(self) -> str:
        band = (f"{self.low_hz:.3g}-{self.high_hz:.3g} Hz" if self.low_hz is not None and
                self.high_hz is not None else "none")
        dec = f"decimated by {self.decimation} to {self.sample_rate_hz:g} Hz" if self.decimation > 1 \
            else f"no decimation ({self.sample_rate_hz:g} Hz)"
        return f"band {band} ({self.source}), {dec}, {self.block_rows} block rows"


def nominal_frequencies(spec: Any, n_modes: int) -> list[float]:
    """The lowest ``n_modes`` natural frequencies of a structure spec's nominal model (Hz)."""
    model = spec.model_kind.build(spec)
    return [float(f) for f in model.modes(n_modes=n_modes).frequencies_hz]


def band_frequencies(spec: Any, band: str, n_modes: int) -> tuple[list[float] | None, str | None]:
    """The nominal frequencies that set the band of interest (``band`` auto or model), or
    ``(None, why not)``: a model kind that cannot be built leaves the band to the spectrum. Used
    alike by the ``identify`` command and node, so a structure file gives the same band in both."""
    if band not in (BandSource.AUTO, BandSource.MODEL):
        return None, None
    from shm_ros.errors import ShmError

    try:
        return nominal_frequencies(spec, n_modes), None
    except (ShmError, NotImplementedError, ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        # a kind without a model, or one that does not build: the spectrum decides instead
        return None, f"no nominal frequencies ({exc}): band from the spectrum"


def band_from_model(frequencies_hz: list[float] | np.ndarray, modes: int, margin: float
                    ) -> tuple[float, float, str] | None:
    """``(low, high, reason)`` from the nominal model's frequencies (its lowest ``modes``)."""
    f = np.sort(np.asarray([x for x in frequencies_hz if x > 0 and math.isfinite(x)], float))[:max(1, modes)]
    if f.size == 0:
        return None
    return (float(f[0]), float(f[-1] * margin),
            f"nominal model modes 1-{f.size}: {f[0]:.3g}-{f[-1]:.3g} Hz, margin x{margin:g}")


def _welch_segments(n: int, fs: float, segment: int | None) -> tuple[int, int, int]:
    """``(nperseg, step, count)`` of the Welch segments: 1/16 of the record (about 30 averages
    with the half overlap), at least 256 samples, at most the power of two >= 40 s (a resolution
    of 0.025 Hz); scipy's segmentation (no padding, overlap ``nperseg // 2``)."""
    seg = segment or int(min(max(256, n // 16), 2 ** math.ceil(math.log2(40 * fs))))
    seg = max(1, min(seg, n))
    step = seg - seg // 2
    return seg, step, (n - seg // 2) // step


def first_singular_spectrum(y: np.ndarray, fs: float, segment: int | None = None
                            ) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies and first singular value of the Welch spectral matrix of the (unit-variance)
    channels (Hann window, constant detrend per segment, half overlap, density scaling: the
    matrix ``scipy.signal.csd`` gives pair by pair).

    Built for cost (about 0.3 s -> 0.02 s of CPU for 10 minutes of 12 channels at 100 Hz), with
    the same spectrum to single-precision rounding, so the band it leads to is the same:

    * every channel's segments are transformed once (``csd`` pair by pair transformed each
      channel 2c times, 78 calls for 12 channels), and the spectral matrix of every bin is one
      small product ``X X^H`` over the segments;
    * the constant detrend is applied after the transform: the Hann window's transform has three
      non-zero bins, so removing a segment's mean only changes bins 0 and 1, corrected there;
    * windowing, transforms and products run in single precision (halves the memory traffic, the
      transforms run twice as fast): the channels are centred and scaled first, so the rounding is
      relative to each channel's own level (~1e-6 of a bin's value where that bin is within 6
      decades of the strongest; the band uses peaks within 4 decades of the highest, and bins more
      than ~12 decades down, rounding in either precision, only ever serve as deep valleys);
    * the largest eigenvalue of each Hermitian matrix (= first singular value) in double precision:
      the eigenvalues are what remains of the cost (~60 %). Power iteration is cheaper but does
      not converge where the leading eigenvalues are close (the noise floor between modes, the
      valleys that set a peak's prominence), and there its Rayleigh quotient is low by up to ~10 %.
    """
    y = np.asarray(y, dtype=float)
    n, c = y.shape
    seg, step, k = _welch_segments(n, fs, segment)
    d = y - np.ones(n) @ y / n  # the record mean removed (a constant: detrended per segment anyway)
    sd = np.sqrt(np.einsum("ij,ij->j", d, d) / n)
    z = np.empty(d.shape, np.float32)  # unit variance
    scale = 1.0 / np.where(sd > 0, sd, 1.0)
    np.multiply(d, scale, out=z, casting="same_kind")
    win = sig.get_window("hann", seg)  # periodic, as welch/csd take it
    segs = np.lib.stride_tricks.sliding_window_view(z, seg, axis=0)[::step][:k]  # (k, c, seg) view
    x = sp_fft.rfft(segs * win.astype(np.float32), axis=2)  # (k, c, bins), complex64
    # each segment's own mean (the constant detrend), from half-segment sums when they tile it
    if seg == 2 * step:
        h = np.ones(step) @ d[:(k + 1) * step].reshape(k + 1, step, c)  # half-segment sums
        means = (h[:-1] + h[1:]) / seg * scale
    else:
        means = segs.mean(axis=2, dtype=np.float64)
    w_hat = sp_fft.rfft(win)
    nz = np.flatnonzero(np.abs(w_hat) > 1e-9 * np.abs(w_hat[0]))  # bins 0 and 1 for Hann
    x[:, :, nz] -= (means[:, :, None] * w_hat[nz]).astype(np.complex64)
    xf = np.ascontiguousarray(x.transpose(2, 1, 0))  # (bins, c, k)
    g = (xf.conj() @ xf.transpose(0, 2, 1)).astype(np.complex128)  # csd's conj(X_a) X_b, summed
    s1 = np.linalg.eigvalsh(g)[:, -1]  # Hermitian: largest eigenvalue = first singular value
    s1 *= 1.0 / (fs * float(np.sum(win * win)) * k)  # density scaling, mean over the segments
    s1[1:-1 if seg % 2 == 0 else None] *= 2.0  # one-sided: all but 0 Hz (and Nyquist if even)
    return sp_fft.rfftfreq(seg, 1.0 / fs), s1


def band_from_spectrum(y: np.ndarray, fs: float, margin: float, prominence_decades: float = 0.7,
                       within_decades: float = 4.0) -> tuple[float, float, str] | None:
    """``(low, high, reason)``: the band of the prominent peaks of the first singular value of
    the spectral matrix (:func:`first_singular_spectrum`, :func:`band_from_singular_spectrum`)."""
    f, s1 = first_singular_spectrum(y, fs)
    return band_from_singular_spectrum(f, s1, fs, margin, prominence_decades, within_decades)


def band_from_singular_spectrum(f: np.ndarray, s1: np.ndarray, fs: float, margin: float,
                                prominence_decades: float = 0.7, within_decades: float = 4.0
                                ) -> tuple[float, float, str] | None:
    """``(low, high, reason)`` from a first singular value spectrum: its prominent peaks
    (prominence >= ``prominence_decades`` in log10, height within ``within_decades`` of the highest
    peak, from the third frequency bin of the Welch segments up)."""
    # above the Hann window's main lobe around 0 Hz (2 bins): a short record's segments are short,
    # and 4 bins (the former limit) left out the first mode of a 1.15 Hz building in 40 s records
    ok = (f > 2.5 * f[1]) & (f < 0.45 * fs) & (s1 > 0)
    if np.count_nonzero(ok) < 8:
        return None
    logs = np.log10(np.where(s1 > 0, s1, np.min(s1[s1 > 0])))
    idx, _ = sig.find_peaks(logs, prominence=prominence_decades)
    idx = idx[ok[idx]]
    if idx.size == 0:
        return None
    idx = idx[logs[idx] >= logs[idx].max() - within_decades]
    lo, hi = float(f[idx[0]]), float(f[idx[-1]])
    return (lo, hi * margin, f"{idx.size} prominent spectral peaks {lo:.3g}-{hi:.3g} Hz "
            f"(first singular value, prominence >= {prominence_decades:g} decades), margin x{margin:g}")


def choose_resolution(fs: float, band: tuple[float, float, str] | None, source: str, *,
                      default_rows: int, rows: int | None, decimate: bool, periods: float,
                      max_block_rows: int) -> BandChoice:
    """Decimation factor and block rows for ``band`` at the rate ``fs``. ``rows`` (explicit block
    rows) and ``decimate=False`` (an explicit target rate, or the band off) win."""
    reasons: list[str] = []
    if band is None:
        reasons.append("no band of interest found" if source != BandSource.OFF else "band: off")
        return BandChoice("none" if source != BandSource.OFF else "off", None, None, 1, fs,
                          rows or default_rows, reasons)
    lo, hi, why = band
    reasons.append(why)
    q = 1
    if decimate:
        q = max(1, int(math.floor(PASS_FRACTION * fs / hi + 1e-9))) if hi > 0 else 1
        reasons.append(f"decimation {q}: band top {hi:.3g} Hz below {PASS_FRACTION:g} x the rate"
                       if q > 1 else f"no decimation: band top {hi:.3g} Hz near the Nyquist rate")
    else:
        reasons.append("decimation as configured (explicit target rate or none)")
    fs_d = fs / q
    if rows is not None:
        i = int(rows)
        reasons.append(f"block rows {i}: explicit")
    else:
        need = int(math.ceil(periods * fs_d / lo))
        i = max(default_rows, min(need, max_block_rows))
        span = i / fs_d * lo
        reasons.append(f"block rows {i}: {i / fs_d:.3g} s = {span:.2g} periods of {lo:.3g} Hz "
                       f"(wanted >= {periods:g}, at least {default_rows}, at most {max_block_rows})")
    return BandChoice(source, lo, hi, q, fs_d, i, reasons)
