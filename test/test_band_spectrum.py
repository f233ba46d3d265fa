"""The automatic band's output spectrum (``first_singular_spectrum``, core/band.py) against the
spectral matrix ``scipy.signal.csd`` gives pair by pair, and the band it leads to.

The fast spectrum transforms each channel once, removes the segment means after the transform and
runs in single precision; the reference below is the pair-by-pair construction it replaced
(independent code: scipy's own segmentation, detrend, window and scaling). Deterministic, so no
statistical threshold: on every simulated window the band (low, high), the decimation and the
block rows must be equal, and the spectrum must agree to 1e-4 relative in every bin within 6
decades of its maximum (single precision rounding gives at most 3e-6 there on these records and on
the steel-frame and CSMIP records; 1e-4 is 0.00004 decades, far below the 0.7-decade prominence
the peaks are selected with) and to 0.01 decades down to 10 decades (the rounding is relative to
a channel's level: 5e-4 in the anti-alias stop band 9.6 decades down in the steel-frame record).
Deeper bins are single-precision rounding (a factor up to 2 at 15-16 decades in the filtered
CSMIP record) and are not compared: the band uses peaks within 4 decades of the highest, and a
valley that deep is a base of more than 10 decades of prominence against the 0.7 wanted.
Windows: ambient vibration of 12-floor buildings (12 and 6 channels, 100 and 40 Hz, gravity
offsets and drift), earthquake responses of an 8-storey building (40 s records, 256-sample
segments), the low-frequency moment frame of ``test/lowfreq_frame.py`` (7 minutes, a measured
shaker input among the channels) and white noise (no band: both must say so). ``SHM_FULL=1`` runs more seeds.
"""

from __future__ import annotations

import math

import lowfreq_frame as lf
import numpy as np
import pytest
import scipy.signal as sig
import synthetic_oma as so
from conftest import full_size

from shm_ros.core.band import band_from_singular_spectrum, choose_resolution, first_singular_spectrum
from shm_ros.core.preprocess import PreprocessConfig, preprocess
from shm_ros.io.importers import read_v2

N_SEEDS = 8 if full_size() else 3
RTOL = 1e-4  # relative, in bins within DECADES of the maximum
DECADES = 6.0
LOG_TOL = 0.01  # decades, in bins within DEEP decades of the maximum
DEEP = 10.0


def reference_spectrum(y: np.ndarray, fs: float, segment: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The spectral matrix pair by pair with ``scipy.signal.csd`` (the former implementation)."""
    n, c = y.shape
    sd = y.std(axis=0)
    z = y / np.where(sd > 0, sd, 1.0)
    seg = segment or int(min(max(256, n // 16), 2 ** math.ceil(math.log2(40 * fs))))
    seg = min(seg, n)
    f, _ = sig.welch(z[:, 0], fs=fs, nperseg=seg)
    g = np.zeros((f.size, c, c), complex)
    for a in range(c):
        for b in range(a, c):
            _, p = sig.csd(z[:, a], z[:, b], fs=fs, nperseg=seg)
            g[:, a, b] = p
            g[:, b, a] = np.conj(p)
    return f, np.linalg.eigvalsh(g)[:, -1]


def _assert_close(s1: np.ndarray, s0: np.ndarray, name: str) -> None:
    assert np.all(s0 > 0) and np.all(s1 > 0), name
    near = s0 >= s0.max() * 10.0 ** -DECADES
    np.testing.assert_allclose(s1[near], s0[near], rtol=RTOL, atol=0, err_msg=name)
    mid = s0 >= s0.max() * 10.0 ** -DEEP
    np.testing.assert_allclose(np.log10(s1[mid]), np.log10(s0[mid]), rtol=0, atol=LOG_TOL, err_msg=name)


def _windows() -> list[tuple[str, np.ndarray, float]]:
    out: list[tuple[str, np.ndarray, float]] = []
    for s in range(N_SEEDS):
        y, fs, _, _ = so.ambient_record(100 + s, duration=300.0, fs=100.0, n_sensors=12)
        out.append((f"ambient 12 ch 100 Hz seed {100 + s}", np.asarray(y), fs))
        y, fs, _, _ = so.ambient_record(200 + s, duration=600.0, fs=40.0, n_sensors=6)
        out.append((f"ambient 6 ch 40 Hz seed {200 + s}", np.asarray(y) + 9.81, fs))  # gravity
        y, _, fs, _ = so.earthquake_record(300 + s)
        out.append((f"earthquake seed {300 + s}", np.asarray(y), fs))
    for s in range(max(1, N_SEEDS // 2)):
        case = lf.frame_case(s)
        out.append((f"frame seed {s}", np.asarray(case.window.samples, float), case.window.sample_rate_hz))
    y, fs = so.white_noise_record(0, duration=300.0)
    out.append(("white noise", np.asarray(y), fs))
    return out


@pytest.fixture(scope="module")
def windows() -> list[tuple[str, np.ndarray, float]]:
    with so.single_blas_thread():
        return _windows()


def test_fast_spectrum_equals_the_pairwise_csd(windows):
    for name, y, fs in windows:
        f0, s0 = reference_spectrum(y, fs)
        f1, s1 = first_singular_spectrum(y, fs)
        np.testing.assert_array_equal(f1, f0, err_msg=name)
        _assert_close(s1, s0, name)


@pytest.mark.parametrize("segment", [255, 300, 1001])
def test_fast_spectrum_odd_and_untiled_segments(segment):
    """Odd lengths (one-sided scaling without a Nyquist bin) and segments whose halves do not tile
    them (the segment means taken directly), on a record with a large offset and a drift."""
    y, fs, _, _ = so.ambient_record(7, duration=120.0, fs=40.0, n_sensors=6)
    y = np.asarray(y) + 9.81 + np.linspace(0, 0.5, len(y))[:, None]
    f0, s0 = reference_spectrum(y, fs, segment)
    f1, s1 = first_singular_spectrum(y, fs, segment)
    np.testing.assert_array_equal(f1, f0)
    _assert_close(s1, s0, f"segment {segment}")


def test_band_decimation_and_block_rows_equal_the_full_spectrum(windows):
    found = 0
    for name, y, fs in windows:
        bands = [band_from_singular_spectrum(*spectrum(y, fs), fs, 1.3)
                 for spectrum in (reference_spectrum, first_singular_spectrum)]
        assert bands[1] == bands[0], name
        choices = [choose_resolution(fs, b, "spectrum", default_rows=20, rows=None, decimate=True,
                                     periods=2.0, max_block_rows=200) for b in bands]
        assert choices[1] == choices[0], name
        found += bands[0] is not None
        if name == "white noise":
            assert bands[0] is None  # no peaks: the comparison above covered "no band" too
    assert found == len(windows) - 1  # every structural window has a band: not a None == None check


def test_real_records_same_band(test_data):
    """The records the identify tests take a band from by spectrum: the steel frame (decimated to
    64 Hz as ``test_identify_real.py`` does) and the CSMIP bridge's deck channels (pre-processed
    as ``test_identify_csmip_peer.py`` does, inputs left out as ``identify`` leaves them out)."""
    records = []
    for setup in (2, 5):
        raw = np.load(test_data / "pyoma_steel_frame" / f"measurement_{setup}.npy").astype(np.float64)
        prep = preprocess(raw, 256.0, [f"c{i}" for i in range(raw.shape[1])],
                          PreprocessConfig(target_rate_hz=64.0))
        records.append((f"steel frame setup {setup}", prep.data, prep.sample_rate_hz))
    rec = read_v2(test_data / "csmip_v2_sample" / "Inglewood_17May2009_CE13795P.zip")[0]
    deck = [6, 7, 8, 10, 11, 12]  # the deck channels (bench/bench_peers_io.py BRIDGE_OUTPUTS)
    prep = preprocess(rec.samples[:, [c - 1 for c in deck]], rec.sample_rate_hz,
                      [rec.channel_names[c - 1] for c in deck])
    records.append(("CSMIP bridge deck", prep.data, prep.sample_rate_hz))
    for name, y, fs in records:
        f0, s0 = reference_spectrum(y, fs)
        f1, s1 = first_singular_spectrum(y, fs)
        _assert_close(s1, s0, name)
        band = band_from_singular_spectrum(f0, s0, fs, 1.3)
        assert band is not None, name
        assert band_from_singular_spectrum(f1, s1, fs, 1.3) == band, name
