"""The window's RMS covariate (``rms_accel_m_s2``): the median over usable output channels of the RMS
about each channel's least-squares line, the same whether every sample is finite (all channels at
once) or some are not (channel by channel, finite samples only)."""

from __future__ import annotations

import numpy as np

from shm_ros.core.ingest.covariates import rms_accel


def _reference(x: np.ndarray, channels: list[int]) -> float:
    out = []
    for c in channels:
        ok = np.isfinite(x[:, c])
        t = np.flatnonzero(ok).astype(float)
        fit = np.polyval(np.polyfit(t, x[ok, c], 1), t)
        out.append(np.sqrt(np.mean((x[ok, c] - fit) ** 2)))
    return float(np.median(out))


def test_rms_about_the_line_median_over_usable_channels():
    rng = np.random.default_rng(3)
    n, names = 5000, ["a", "b", "g0", "c", "d"]
    x = rng.standard_normal((n, 5)) * [0.01, 0.02, 0.5, 0.03, 0.04] + np.linspace(0, 2, n)[:, None] + 9.81
    status = ["ok", "ok", "ok", "ok", "dead"]
    got = rms_accel(x, names, status, input_channel="g0")
    assert np.isclose(got, _reference(x, [0, 1, 3]), rtol=1e-9)
    x[[10, 700], 1] = np.nan  # the channel-by-channel path: finite samples of that channel only
    assert np.isclose(rms_accel(x, names, status, input_channel="g0"), _reference(x, [0, 1, 3]), rtol=1e-9)
    assert rms_accel(x[:2], names) is None and rms_accel(x, ["g0"] * 5, input_channel="g0") is None
