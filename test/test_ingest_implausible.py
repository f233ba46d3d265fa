"""Ingest reports what a sensor cannot have measured: samples beyond 20 g (configurable) become NaN
with an ``implausible`` diagnostic naming the channel, clock jumps (forward by more than a day, or
any step back) give a ``clock_jump`` diagnostic, and a window shorter than a second is refused (it
would churn out windows too short for any mode)."""

from __future__ import annotations

import numpy as np
import pytest

from shm_ros.core.diagnostics import Level
from shm_ros.core.ingest import ChannelMap, IngestConfig, IngestCore
from shm_ros.core.types import SampleFlag

T0 = 1_714_521_600_000_000_000
FS = 100.0
P = 10_000_000


def _core(**cfg) -> IngestCore:
    return IngestCore(ChannelMap.simple(["a", "b"]), IngestConfig(window_s=10.0, max_latency_s=float("inf"), **cfg))


def _xyz(x):
    out = np.zeros((x.size, 3))
    out[:, 2] = x
    return out


def _diags(core, code):
    return [d for d in core.diagnostics if d.code == code]


@pytest.mark.parametrize("value", [1e298, -250.0, 3e3])
def test_implausible_samples_are_reported_and_not_used(value):
    x = np.random.default_rng(0).standard_normal(2000) * 0.01
    x[700] = value
    core = _core()
    core.add_accel("a", T0 + np.arange(2000) * P, _xyz(x))
    core.add_accel("b", T0 + np.arange(2000) * P, _xyz(np.full(2000, 0.01)))
    ws = core.flush()
    found = _diags(core, "implausible")
    assert len(found) == 1 and found[0].source.startswith("accel/a") and "set to NaN" in found[0].message
    assert core.stats.implausible == 1
    col = ws[0].channel_names.index("a")
    assert np.isnan(ws[0].samples[700, col]) and ws[0].flags[700, col] & SampleFlag.NAN
    assert np.isfinite(ws[0].samples[:, ws[0].channel_names.index("b")]).all()


def test_the_limit_is_configurable_and_defaults_to_20_g():
    assert IngestConfig().implausible_m_s2 == pytest.approx(20 * 9.80665)
    core = _core(implausible_m_s2=5.0)
    core.add_accel("a", T0 + np.arange(1000) * P, _xyz(np.full(1000, 6.0)))
    assert core.stats.implausible == 1000 and _diags(core, "implausible")[0].count == 1000


@pytest.mark.parametrize("step_s, direction", [(365 * 86400.0, "forward"), (-30.0, "back"),
                                               (12 * 365 * 86400.0, "into the future")])
def test_clock_jumps_are_reported(step_s, direction):
    """A step back or into the future is a warning; a long step forward is reported (it may be a
    pause between the records of an event catalogue)."""
    core = _core()
    t = T0 + np.arange(3000) * P
    t[1500:] += int(step_s * 1e9)
    x = np.random.default_rng(1).standard_normal(3000)
    core.add_accel("a", t[:1000], _xyz(x[:1000]))
    core.add_accel("a", t[1000:], _xyz(x[1000:]))  # the jump inside one batch
    jumps = _diags(core, "clock_jump")
    assert jumps and direction in jumps[0].message and jumps[0].source.startswith("accel/a")
    assert jumps[0].level == (Level.OK if direction == "forward" else Level.WARN)
    core2 = _core()
    core2.add_accel("a", t[:1500], _xyz(x[:1500]))
    core2.add_accel("a", t[1500:], _xyz(x[1500:]))  # the jump between two batches
    assert _diags(core2, "clock_jump")


def test_no_diagnostic_on_a_clean_stream():
    core = _core()
    core.add_accel("a", T0 + np.arange(5000) * P, _xyz(np.random.default_rng(2).standard_normal(5000)))
    core.flush()
    assert not _diags(core, "clock_jump") and not _diags(core, "implausible")


@pytest.mark.parametrize("window", [0.01, 0.0, -1.0, float("inf"), float("nan")])
def test_windows_too_short_or_not_finite_are_refused(window):
    with pytest.raises(ValueError, match="window_s must be at least 1 s"):
        IngestConfig(window_s=window)


def test_stamps_too_dense_for_an_accelerometer_ask_for_no_vast_grid():
    """Hostile stamps 1 ns apart (a rate of 1 GHz) or an AccelBlock claiming 1 GHz would make a
    window's grid billions of rows: refused (the fastest rate is 100 kHz), quickly."""
    import time

    core = _core()
    t0 = time.perf_counter()
    t = T0 + np.arange(200)  # 1 ns apart
    core.add_accel("a", np.concatenate([t, t + 3_000_000_000]), _xyz(np.zeros(400)))
    core.add_block(T0, 1e9, ["a"], np.zeros((50, 1)))
    core.flush()
    assert time.perf_counter() - t0 < 5.0
    assert any(d.code == "rejected" and "at most 100000" in d.message for d in core.diagnostics)
    with pytest.raises(ValueError, match="sample_rate_hz"):
        IngestConfig(sample_rate_hz=1e9)
