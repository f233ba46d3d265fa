"""IngestCore: windowing rules, snapping, fault policy and events on hand-made streams."""

from __future__ import annotations

import numpy as np
import pytest

from shm_ros.core.ingest import ChannelMap, ChannelSource, IngestConfig, IngestCore, sta_lta
from shm_ros.core.types import SampleFlag

T0 = 1_714_521_600_000_000_000  # 2024-05-01T00:00:00Z
FS = 200.0
P = 5_000_000  # ns


def offline(channels, **cfg) -> IngestCore:
    cfg.setdefault("max_latency_s", float("inf"))
    return IngestCore(ChannelMap.simple(channels), IngestConfig(**cfg))


def z3(x: np.ndarray) -> np.ndarray:
    out = np.zeros((x.size, 3))
    out[:, 2] = x
    return out


def codes(core: IngestCore) -> set[str]:
    return {code for code, _ in core.diagnostic_counts}


def test_windows_half_open_contiguous_remainder_kept_at_half():
    n = int(25.0 * FS)  # 2.5 windows of 10 s
    x = np.random.default_rng(0).standard_normal(n)
    core = offline(["a"], window_s=10.0)
    core.add_accel("a", T0 + np.arange(n) * P, z3(x))
    ws = core.flush()
    assert [w.n_samples for w in ws] == [2000, 2000, 1000]  # 5 s is not shorter than half
    for i, w in enumerate(ws):
        assert w.start_ns == T0 + i * 2000 * P
        assert w.end_ns == w.start_ns + (w.n_samples - 1) * P + P  # last sample + one period
    assert ws[0].end_ns == ws[1].start_ns and ws[1].end_ns == ws[2].start_ns
    assert np.array_equal(np.concatenate([w.samples[:, 0] for w in ws]), x)
    assert ws[0].window_id == "2024-05-01T00:00:00.000Z"
    assert not core.dropped


def test_remainder_shorter_than_half_dropped_and_reported():
    n = int(24.9 * FS)
    core = offline(["a"], window_s=10.0)
    core.add_accel("a", T0 + np.arange(n) * P, z3(np.random.default_rng(1).standard_normal(n)))
    ws = core.flush()
    assert [w.n_samples for w in ws] == [2000, 2000]
    assert len(core.dropped) == 1
    d = core.dropped[0]
    assert d.start_ns == T0 + 4000 * P and d.n_samples == n - 4000
    assert "half a window" in d.reason
    assert "remainder_dropped" in codes(core)
    assert core.stats.samples_not_windowed["short_piece"] == n - 4000


def test_bursts_pauses_and_gap_split():
    rng = np.random.default_rng(2)
    # burst 1: 13 s; pause 1.5 s; burst 2: 12 s with a 0.5 s gap at 6 s into it; then 9 s more
    b1 = T0 + np.arange(int(13 * FS)) * P
    start2 = b1[-1] + int(1.5e9)
    k2 = np.arange(int(21 * FS))
    k2 = k2[(k2 < 6 * FS) | (k2 >= 6.5 * FS)]  # 100 grid points missing (0.5 s < 1 s: a gap)
    b2 = start2 + k2 * P
    t = np.concatenate((b1, b2))
    x = rng.standard_normal(t.size)
    core = offline(["a"], window_s=10.0)
    core.add_accel("a", t, z3(x))
    ws = core.flush()
    starts = [(w.start_ns - T0) / 1e9 for w in ws]
    s2 = (start2 - T0) / 1e9
    # burst 1: one full window, 3 s remainder dropped; burst 2 counted from its first sample:
    # [s2, s2+10) split at the gap -> [s2, s2+6) kept (6 s >= 5 s), [s2+6.5, s2+10) dropped (3.5 s),
    # then [s2+10, s2+20) full, remainder 1 s dropped.
    assert starts == pytest.approx([0.0, s2, s2 + 10.0])
    assert [w.n_samples for w in ws] == [2000, 1200, 2000]
    assert any("ends at a gap" in n for n in ws[1].notes)
    reasons = sorted((round((d.start_ns - T0) / 1e9, 3), d.n_samples) for d in core.dropped)
    assert reasons == [(10.0, 600), (round(s2 + 6.5, 3), 700), (round(s2 + 20.0, 3), 200)]
    assert "gap" in codes(core)
    # every kept sample is the one recorded at that time
    for w in ws:
        idx = np.searchsorted(t, w.stamps_ns())
        assert np.array_equal(t[idx], w.stamps_ns())
        assert np.array_equal(w.samples[:, 0], x[idx])


def test_temperature_mean_inside_half_open_window():
    n = int(20 * FS)
    core = offline(["a"], window_s=10.0)
    core.add_accel("a", T0 + np.arange(n) * P, z3(np.random.default_rng(3).standard_normal(n)))
    core.add_temperature("t1", T0 + int(1e9), 10.0)
    core.add_temperature("t2", T0 + int(9.9e9), 13.0)
    core.add_temperature("t1", T0 + int(10e9), 30.0)  # exactly at the end of window 1: window 2
    core.add_temperature("t1", T0 + int(25e9), 99.0)  # after everything: no window
    ws = core.flush()
    assert ws[0].temperature_c == pytest.approx(11.5)
    assert ws[1].temperature_c == pytest.approx(30.0)
    core2 = offline(["a"], window_s=10.0)
    core2.add_accel("a", T0 + np.arange(n) * P, z3(np.zeros(n) + np.arange(n) * 1e-3))
    assert all(w.temperature_c is None for w in core2.flush())


@pytest.mark.parametrize("seed", range(12))
def test_separate_imus_snap_with_jitter_below_half_period(seed):
    rng = np.random.default_rng(seed)
    n = int(12 * FS)
    grid = T0 + np.arange(n) * P
    chans = ["a", "b", "c"]
    core = offline(chans, window_s=10.0)
    truth = {}
    for i, c in enumerate(chans):
        # each IMU has its own clock offset and jitter; |offset + jitter| < 0.5 period
        offset = rng.uniform(-0.2, 0.2) * P
        jit = rng.uniform(-0.25, 0.25, n) * P
        stamps = grid + (offset + jit).astype(np.int64)
        if i == 0:
            stamps[0] = grid[0]  # the burst origin is the first stamp
        stamps[0] = max(stamps[0], grid[0])
        x = rng.standard_normal(n) + 9.81 * (i == 0)
        truth[c] = x
        core.add_accel(c, stamps, z3(x))
    ws = core.flush()
    assert [w.n_samples for w in ws] == [2000]
    for j, c in enumerate(chans):
        assert np.array_equal(ws[0].samples[:, j], truth[c][:2000])
    assert ws[0].flags is None and ws[0].channel_status == ["ok"] * 3
    assert not ({"gap", "unsnappable"} & codes(core))


def test_stamp_that_cannot_snap_is_a_gap():
    rng = np.random.default_rng(7)
    n = int(25 * FS)
    grid = T0 + np.arange(n) * P
    xa, xb = rng.standard_normal(n), rng.standard_normal(n)
    tb = grid + (rng.uniform(-0.1, 0.1, n) * P).astype(np.int64)
    tb[0] = grid[0]
    bad = 3000
    tb[bad] = grid[bad] + int(0.7 * P)  # nearer to the next grid point, which is taken by a closer stamp
    core = offline(["a", "b"], window_s=10.0)
    core.add_accel("a", grid, z3(xa))
    core.add_accel("b", tb, z3(xb))
    ws = core.flush()
    # window 2 [10 s, 20 s) splits at row 1000 of it: [10, 15) kept (1000 rows = half), the
    # rest after the gap is 999 rows < half: dropped
    assert [(w.start_ns - T0) // P for w in ws] == [0, 2000, 4000]
    assert [w.n_samples for w in ws] == [2000, 1000, 1000]
    diags = [d for d in core.diagnostics if d.code == "unsnappable"]
    assert diags and "accel/b" in diags[0].source
    assert any(d.code == "gap" and "accel/b" in d.source for d in core.diagnostics)
    assert (ws[1].end_ns - T0) // P == bad
    # nothing kept in any window sits at the wrong time
    for w in ws:
        k = (w.stamps_ns() - T0) // P
        assert np.array_equal(w.samples[:, 1], xb[k])


def test_tolerance_narrower_than_half_makes_a_gap():
    n = int(10 * FS)
    grid = T0 + np.arange(n) * P
    t = grid.copy()
    t[500] += int(0.3 * P)
    core = offline(["a"], window_s=5.0, snap_tolerance=0.25)
    core.add_accel("a", t, z3(np.random.default_rng(8).standard_normal(n)))
    ws = core.flush()
    # [0, 5 s) splits at row 500: 500 rows (= half a window) kept, 499 dropped; [5 s, 10 s) whole
    assert [w.n_samples for w in ws] == [500, 1000]
    assert [(w.start_ns - T0) // P for w in ws] == [0, 1000]
    assert core.diagnostic_counts[("unsnappable", core._src(0))] == 1


def test_faults_flagged_not_dropped():
    rng = np.random.default_rng(9)
    n = int(10 * FS)
    grid = T0 + np.arange(n) * P
    x = 0.01 * rng.standard_normal((n, 4))
    x[:, 0] += 9.81
    x[100, 0] = np.nan
    x[200, 0] = np.inf
    x[:, 1] = 0.5  # dead
    # clipped: a big oscillation flat-topped at +-2
    x[:, 2] = np.clip(3 * np.sin(2 * np.pi * 1.0 * np.arange(n) / FS), -2.0, 2.0)
    x[700, 3] = 5.0  # spike
    core = offline(["a", "b", "c", "d"], window_s=10.0)
    for j, c in enumerate("abcd"):
        core.add_accel(c, grid, z3(x[:, j]))
    (w,) = core.flush()
    assert w.n_samples == n
    assert np.isnan(w.samples[100, 0]) and np.isinf(w.samples[200, 0])
    assert w.flags[100, 0] & SampleFlag.NAN and w.flags[200, 0] & SampleFlag.NAN
    assert w.channel_status[1] == "dead"
    assert w.channel_status[2] == "clipped"
    clipped = (w.flags[:, 2] & SampleFlag.CLIPPED) != 0
    assert np.array_equal(clipped, np.abs(x[:, 2]) == 2.0)
    assert w.flags[700, 3] & SampleFlag.SPIKE and int(((w.flags[:, 3] & SampleFlag.SPIKE) != 0).sum()) == 1
    assert np.array_equal(w.samples[:, 1:], x[:, 1:], equal_nan=True)  # nothing repaired
    for code in ("nan", "dead_channel", "clipped", "spike"):
        assert code in codes(core)


def test_duplicates_and_out_of_order_placed_by_stamp():
    rng = np.random.default_rng(10)
    n = int(10 * FS)
    grid = T0 + np.arange(n) * P
    x = rng.standard_normal(n)
    order = np.arange(n)
    order[[300, 301]] = [301, 300]  # two samples arrive swapped
    t, v = grid[order], x[order]
    t = np.insert(t, 500, t[499])  # a duplicated stamp (resent message, other value)
    v = np.insert(v, 500, 123.0)
    core = offline(["a"], window_s=10.0)
    core.add_accel("a", t, z3(v))
    (w,) = core.flush()
    assert np.array_equal(w.samples[:, 0], x)  # first copy kept, swapped pair in stamp order
    assert w.flags[300, 0] & SampleFlag.OUT_OF_ORDER
    assert w.flags[499, 0] & SampleFlag.DUPLICATE_STAMP
    assert core.diagnostic_counts[("duplicate_stamp", core._src(0))] == 1
    assert core.diagnostic_counts[("out_of_order", "accel/a.z")] == 1


def test_clock_jump_backwards_in_a_stream_is_rejected_and_reported():
    rng = np.random.default_rng(11)
    n = int(30 * FS)
    grid = T0 + np.arange(n) * P
    x = rng.standard_normal(n)
    t = grid.copy()
    t[4000:] -= int(15e9)  # at 20 s the clock jumps back 15 s
    core = IngestCore(ChannelMap.simple(["a"]), IngestConfig(window_s=5.0, max_latency_s=1.0))
    ws = []
    for i in range(0, n, 50):  # streamed in small pieces
        core.add_accel("a", t[i:i + 50], z3(x[i:i + 50]))
        ws += core.pop_windows()
    ws += core.flush()
    assert core.diagnostic_counts[("late_sample", "accel/a.z")] >= 1
    assert sum(d.count for d in core.diagnostics if d.code == "late_sample") > 0
    # the windows before the jump are intact
    assert [(w.start_ns - T0) // P for w in ws[:3]] == [0, 1000, 2000]
    assert np.array_equal(np.concatenate([w.samples[:, 0] for w in ws[:3]]), x[:3000])


def test_channel_mostly_missing_is_dropped_not_split():
    rng = np.random.default_rng(12)
    n = int(10 * FS)
    grid = T0 + np.arange(n) * P
    core = offline(["a", "b"], window_s=10.0)
    core.add_accel("a", grid, z3(rng.standard_normal(n)))
    core.add_accel("b", grid[:300], z3(rng.standard_normal(300)))
    (w,) = core.flush()
    assert w.n_samples == n and w.channel_status == ["ok", "dropped"]
    assert np.isnan(w.samples[300:, 1]).all() and not np.isnan(w.samples[:300, 1]).any()
    assert ((w.flags[300:, 1] & SampleFlag.MISSING) != 0).all()
    assert "channel_dropped" in codes(core)


def test_bad_messages_produce_diagnostics_not_exceptions():
    core = offline(["s1", "s2"], window_s=1.0)
    core.add_block(T0, 200.0, ["s1"], np.zeros((10, 2)))  # shape mismatch
    core.add_block(T0, float("nan"), ["s1"], np.zeros((10, 1)))
    core.add_block(T0, 200.0, ["s1"], np.zeros((10, 1)), units="furlongs/fortnight^2")
    core.add_block(T0, 200.0, ["s1", "zz"], np.zeros((10, 2)))  # unknown channel zz
    core.add_accel_sample("nope", T0, 0.0, 0.0, 9.8)  # unknown topic
    core.add_accel_sample("s1", "not a stamp", 0.0, 0.0, 9.8)
    core.add_temperature("t", "x", 1.0)
    core.flush()
    c = codes(core)
    assert {"rejected", "unknown_channel", "unknown_topic"} <= c
    assert core.stats.messages_rejected >= 4
    srcs = " ".join(d.source for d in core.diagnostics)
    assert "accel_block.units" in srcs and "accel/nope" in srcs


def test_block_units_converted_and_undeclared_g_reported():
    n = int(10 * FS)
    rng = np.random.default_rng(13)
    g = 1.0 + 0.001 * rng.standard_normal((n, 2))
    core = offline(["s1", "s2"], window_s=10.0)
    core.add_block(T0, FS, ["s1", "s2"], g, units="g")
    (w,) = core.flush()
    assert np.array_equal(w.samples, g * 9.80665)
    assert "units" not in codes(core)
    core2 = offline(["s1", "s2"], window_s=10.0)
    core2.add_block(T0, FS, ["s1", "s2"], g, units="m/s^2")  # declared wrongly
    (w2,) = core2.flush()
    assert np.array_equal(w2.samples, g)  # not rescaled
    assert "units" in codes(core2) and any("look like g" in n for n in w2.notes)


def test_block_rate_mismatch_rejected():
    core = offline(["s1"], window_s=1.0)
    core.add_block(T0, 200.0, ["s1"], np.zeros((200, 1)) + np.arange(200)[:, None])
    core.add_block(T0 + int(1e9), 250.0, ["s1"], np.zeros((250, 1)))
    core.flush()
    assert any(d.code == "rejected" and "sample_rate_hz" in d.source for d in core.diagnostics)


def _ambient(rng, n, c):
    """Coloured ambient vibration (two lightly damped resonances driven by white noise)."""
    from scipy.signal import lfilter

    out = np.empty((n, c))
    for j in range(c):
        e = rng.standard_normal(n)
        y = np.zeros(n)
        for f, z in ((2.3, 0.01), (7.1, 0.02)):
            r = np.exp(-2 * np.pi * f * z / FS)
            th = 2 * np.pi * f / FS
            y += lfilter([1.0], [1.0, -2 * r * np.cos(th), r * r], e)
        out[:, j] = 0.01 * y / y.std() + 9.81 * (j == 0) + 2e-4 * rng.standard_normal(n)
    return out


def test_events_detected_over_seeds_and_ambient_not():
    hits, false = 0, 0
    for seed in range(8):
        rng = np.random.default_rng(100 + seed)
        n = int(120 * FS)
        amb = _ambient(rng, n, 3)
        t = np.arange(n) / FS
        t_on = rng.uniform(50, 90)
        env = np.where(t > t_on, (t - t_on) * np.exp(-(t - t_on) / 3.0), 0.0)
        quake = env[:, None] * np.sin(2 * np.pi * rng.uniform(1, 5) * t)[:, None] * rng.uniform(0.2, 1.0, 3)
        for data, is_q in ((amb, False), (amb + quake, True)):
            core = offline(["a", "b", "c"], window_s=120.0)
            core.add_block(T0, FS, ["a", "b", "c"], data)
            (w,) = core.flush()
            if is_q:
                hits += w.is_event
                assert w.pga_m_s2 == pytest.approx(np.max(np.abs(data - np.median(data, axis=0))), rel=1e-9)
            else:
                false += w.is_event
    assert hits == 8 and false == 0


def test_sta_lta_ratio_is_one_on_stationary_noise():
    x = np.random.default_rng(5).standard_normal(200 * 200)
    r = sta_lta(x, 200.0, 1.0, 30.0)
    assert 0.5 < np.median(r[6000:]) < 1.5
    assert r[:399].max() == 0.0 and r[399:].min() > 0.0  # expanding LTA from 2 STA lengths on


def test_no_spikes_flagged_on_band_limited_or_strong_shaking():
    from scipy.signal import butter, sosfilt

    flagged = 0
    for seed in range(10):
        rng = np.random.default_rng(300 + seed)
        n = int(60 * FS)
        sos = butter(4, [0.5, 15.0], btype="band", fs=FS, output="sos")
        x = sosfilt(sos, rng.standard_normal(n)) * 0.01
        t = np.arange(n) / FS
        env = np.where(t > 20, (t - 20) * np.exp(-(t - 20) / 2.0), 0.0)  # a burst of shaking
        x = x + env * sosfilt(sos, rng.standard_normal(n))
        core = offline(["a"], window_s=60.0)
        core.add_block(T0, FS, ["a"], x[:, None])
        (w,) = core.flush()
        flagged += 0 if w.flags is None else int(((w.flags & SampleFlag.SPIKE) != 0).sum())
        x2 = x.copy()
        x2[int(5 * FS)] += 0.5  # a real spike in the quiet part is still found
        core = offline(["a"], window_s=60.0)
        core.add_block(T0, FS, ["a"], x2[:, None])
        (w2,) = core.flush()
        assert w2.flags is not None and w2.flags[int(5 * FS), 0] & SampleFlag.SPIKE
    assert flagged == 0


def test_streaming_per_sample_equals_offline_arrays():
    rng = np.random.default_rng(21)
    n = int(33 * FS)
    grid = T0 + np.arange(n) * P
    xa, xb = rng.standard_normal((n, 3)), rng.standard_normal((n, 3))
    tb = grid + (rng.uniform(-0.3, 0.3, n) * P).astype(np.int64)
    tb[0] = grid[0] + 1
    off = offline(["a", "b"], window_s=10.0)
    off.add_accel("a", grid, xa)
    off.add_accel("b", tb, xb)
    ref = off.flush()
    live = IngestCore(ChannelMap.simple(["a", "b"]), IngestConfig(window_s=10.0, max_latency_s=0.5))
    got = []
    for i in range(n):
        live.add_accel_sample("a", int(grid[i]), *xa[i])
        live.add_accel_sample("b", int(tb[i]), *xb[i])
        got += live.pop_windows()
    assert len(got) >= 2  # windows come out while streaming, not only at the end
    got += live.flush()
    assert [w.start_ns for w in got] == [w.start_ns for w in ref]
    for a, b in zip(got, ref, strict=True):
        assert np.array_equal(a.samples, b.samples)


def _stream(core, chans, stamps, values, delays_s, upto_s):
    """Feed, in arrival order, every sample whose arrival time (stamp + the channel's delay) is
    before ``upto_s`` after T0 and that was not fed yet; returns the windows cut meanwhile."""
    fed = getattr(core, "_test_fed", {c: 0 for c in chans})
    core._test_fed = fed
    events = []
    for c in chans:
        t = stamps[c]
        arrive = (t - T0) / 1e9 + delays_s[c]
        k1 = int(np.searchsorted(arrive, upto_s))
        events += [(arrive[k], c, k) for k in range(fed[c], k1)]
        fed[c] = k1
    for _, c, k in sorted(events):
        core.add_accel_sample(c, int(stamps[c][k]), *values[c][k])
    return core.pop_windows()


def test_streaming_cuts_once_every_channel_settled_and_waits_for_a_lagging_one():
    """settle_s: a window is cut as soon as every channel is settle_s past its end, long before
    max_latency_s; a lagging channel (delivered 4 s late) holds the cut back and loses nothing; a
    channel that falls silent holds it until the median rule (max_latency_s) closes it."""
    rng = np.random.default_rng(8)
    n = int(45 * FS)
    chans = ["a", "b", "c"]
    grid = T0 + np.arange(n) * P
    stamps = {c: grid for c in chans}
    values = {c: rng.standard_normal((n, 3)) for c in chans}
    off = offline(chans, window_s=10.0)
    for c in chans:
        off.add_accel(c, grid, values[c])
    ref = off.flush()
    cfg = dict(window_s=10.0, max_latency_s=120.0, settle_s=0.5)
    # all channels on time: window [0, 10) is out once every channel passed 10.5 s
    live = IngestCore(ChannelMap.simple(chans), IngestConfig(**cfg))
    on_time = {c: 0.0 for c in chans}
    assert _stream(live, chans, stamps, values, on_time, 10.4) == []
    first = _stream(live, chans, stamps, values, on_time, 10.6)
    assert [w.start_ns for w in first] == [ref[0].start_ns]
    assert np.array_equal(first[0].samples, ref[0].samples)
    # channel b arrives 4 s late: nothing is cut before b itself passed the end, nothing is lost
    late = IngestCore(ChannelMap.simple(chans), IngestConfig(**cfg))
    delays = {"a": 0.0, "b": 4.0, "c": 0.0}
    assert _stream(late, chans, stamps, values, delays, 14.4) == []
    got = _stream(late, chans, stamps, values, delays, 14.6)
    got += _stream(late, chans, stamps, values, delays, 100.0) + late.flush()
    assert [w.start_ns for w in got] == [w.start_ns for w in ref]
    for a, b in zip(got, ref, strict=True):
        assert np.array_equal(a.samples, b.samples)
    # channel c silent after 12 s: window [10, 20) waits for the median rule, not for settle_s
    silent = IngestCore(ChannelMap.simple(chans), IngestConfig(**cfg))
    cut = {c: grid[: int(12 * FS)] if c == "c" else grid for c in chans}
    vals = {c: values[c][: cut[c].size] for c in chans}
    out = _stream(silent, chans, cut, vals, on_time, 45.0)
    assert [w.start_ns for w in out] == [ref[0].start_ns]  # only the window before c stopped
    # without settle_s the same live feed cuts nothing within 45 s
    plain = IngestCore(ChannelMap.simple(chans), IngestConfig(window_s=10.0, max_latency_s=120.0, settle_s=None))
    assert _stream(plain, chans, stamps, values, on_time, 45.0) == []
    with pytest.raises(ValueError, match="settle_s"):
        IngestConfig(settle_s=-1.0)


def test_channel_map_from_structure_sources():
    from types import SimpleNamespace as NS

    spec = NS(sensors=[NS(id="f8", source=NS(topic="f8", axis="x", sign=1.0, channel="f8")),
                       NS(id="f8y", source=NS(topic="f8", axis="y", sign=-1.0, channel=None)),
                       NS(id="g0", source=NS(topic=None, axis="x", sign=1.0, channel="ground"))],
              input_sensor="g0")
    cmap = ChannelMap.from_structure(spec)
    core = IngestCore(cmap, IngestConfig(window_s=1.0, max_latency_s=float("inf")))
    n = 400
    xyz = np.random.default_rng(3).standard_normal((n, 3))
    core.add_accel("f8", T0 + np.arange(n) * P, xyz)
    core.add_block(T0, FS, ["ground"], xyz[:, :1] * 2)
    ws = core.flush()
    assert [w.channel_names for w in ws][0] == ["f8", "f8y", "g0"]
    s = np.concatenate([w.samples for w in ws])
    assert np.array_equal(s[:, 0], xyz[:, 0]) and np.array_equal(s[:, 1], -xyz[:, 1])
    assert np.array_equal(s[:, 2], 2 * xyz[:, 0])
    assert ws[0].input_channel == "g0"


def test_tick_closes_a_burst_that_has_ended_without_new_data():
    rng = np.random.default_rng(31)
    n = int(7 * FS)
    core = IngestCore(ChannelMap.simple(["a"]), IngestConfig(window_s=10.0, max_latency_s=0.5))
    x = rng.standard_normal(n)
    for i in range(n):
        core.add_accel_sample("a", T0 + i * P, 0.0, 0.0, float(x[i]))
    assert core.pop_windows() == []  # 7 s of a 10 s window: the burst may still go on
    core.tick(T0 + n * P + int(0.8e9))  # 0.8 s later: not yet a pause (> 1 s) after the latency
    assert core.pop_windows() == []
    core.tick(T0 + n * P + int(2.0e9))
    (w,) = core.pop_windows()  # 7 s >= half of 10 s: kept
    assert w.n_samples == n and np.array_equal(w.samples[:, 0], x)
    assert any(d.code == "burst" for d in core.pop_diagnostics())
    assert core.pop_diagnostics() == []  # popped once


def _accounted(core: IngestCore) -> bool:
    """Every channel sample handed in is in a window or counted with the reason it is not."""
    st = core.stats
    return st.samples_in == st.samples_windowed + sum(st.samples_not_windowed.values())


@pytest.mark.parametrize("seed", range(4))
def test_random_garbage_never_raises_and_loses_nothing(seed):
    rng = np.random.default_rng(77 + seed)
    core = IngestCore(ChannelMap.simple(["a", "b"]), IngestConfig(window_s=2.0, max_latency_s=0.5))
    t = T0
    for _ in range(3000):
        t += int(rng.choice([P, P, P, 0, -P, 3 * P, int(2e9), -int(5e9)]))
        r = rng.random()
        if r < 0.6:
            v = rng.choice([0.1, np.nan, np.inf, 1e30, -3.0])
            core.add_accel_sample(str(rng.choice(["a", "b", "zz"])), t, 0.0, 0.0, float(v))
        elif r < 0.8:
            shape = [(5, 2), (0, 2), (3,), (2, 2, 2), (4, 1)][rng.integers(5)]
            names = ["a", "b"][: shape[-1] if len(shape) > 1 else 2]
            core.add_block(t, float(rng.choice([200.0, 0.0, np.nan, 100.0])), names,
                           rng.standard_normal(shape), units=str(rng.choice(["m/s^2", "g", "??"])))
        elif r < 0.9:
            core.add_temperature("t", t, float(rng.choice([12.0, np.nan])))
        else:
            core.tick(t)
        core.pop_windows()
    core.flush()
    c = codes(core)
    assert {"rejected", "unknown_topic", "late_sample", "nan"} <= c
    assert core.stats.samples_in > 0 and _accounted(core)


W5 = 1000  # rows of a 5 s window
VALUE_FAULTS = ("nan", "spike", "clipped", "dead_channel")
STAMP_FAULTS = ("duplicate_stamp", "out_of_order", "unsnappable", "gap")


@pytest.mark.parametrize("seed", range(6))
def test_injected_faults_are_reported_for_their_channel_and_time(seed):
    """A live core fed three channels (a per sample, b in arrays, c in AccelBlocks) with one fault
    per 5 s window, chosen at random: each fault gives its diagnostic code, for its channel and its
    time; every accepted sample is in a window at its stamp or counted with the reason it is not."""
    rng = np.random.default_rng(900 + seed)
    n_win = 14
    n = n_win * W5
    chans = ["a", "b", "c"]
    truth = {c: 0.01 * rng.standard_normal(n) for c in chans}
    # arrival lists per channel: (arrival key, stamp, value); the key orders the feed
    feed = {c: [(float(i), int(T0 + i * P), 0.0) for i in range(n)] for c in chans}
    faults = []  # (code, channel, stamp of the fault or None, window index)
    kinds = list(VALUE_FAULTS + STAMP_FAULTS)
    rng.shuffle(kinds)
    for win, kind in zip(range(1, n_win - 1), kinds * 2, strict=False):
        ch = str(rng.choice(chans if kind in VALUE_FAULTS else ["a", "b"]))
        i = win * W5 + int(rng.integers(600, 900))  # late in the window: the piece before a gap is kept
        x = truth[ch]
        if kind == "nan":
            x[i] = np.nan
        elif kind == "spike":
            x[i] += 1.0
        elif kind == "clipped":
            x[i:i + 10] = 2.0
        elif kind == "dead_channel":
            x[win * W5:(win + 1) * W5] = 0.3
        elif kind == "duplicate_stamp":
            feed[ch].append((i + 0.5, int(T0 + i * P), 123.0))
        elif kind == "out_of_order":
            feed[ch][i], feed[ch][i + 1] = (i + 1.0, *feed[ch][i][1:]), (float(i), *feed[ch][i + 1][1:])
        elif kind == "unsnappable":
            feed[ch][i] = (float(i), int(T0 + i * P + 0.7 * P), 0.0)
        elif kind == "gap":
            for j in range(i, i + 20):
                feed[ch][j] = (float(j), -1, 0.0)  # not sent
        faults.append((kind, ch, int(feed[ch][i][1]) if kind == "unsnappable" else int(T0 + i * P), win))
    core = IngestCore(ChannelMap.simple(chans), IngestConfig(window_s=5.0, max_latency_s=0.5, max_repeats=100))
    streams = {}
    for c in chans:
        rows = sorted(r for r in feed[c] if r[1] >= 0)
        t = np.array([r[1] for r in rows], np.int64)
        idx = (t - T0) // P  # the sample of that stamp (an unsnappable one is 0.7 period late)
        v = np.array([r[2] if r[2] else truth[c][k] for r, k in zip(rows, idx.tolist(), strict=True)])
        streams[c] = (np.array([r[0] for r in rows]), t, v)
    windows = []
    for j in range(0, n, 40):  # 0.2 s of arrivals at a time
        for c in chans:
            key, t, v = streams[c]
            sel = (key >= j) & (key < j + 40)
            if c == "a":
                for tt, vv in zip(t[sel].tolist(), v[sel].tolist(), strict=True):
                    core.add_accel_sample("a", tt, 0.0, 0.0, vv)
            elif c == "b":
                core.add_accel("b", t[sel], np.column_stack((np.zeros(sel.sum()), np.zeros(sel.sum()), v[sel])))
            else:
                core.add_block(int(t[sel][0]), FS, ["c"], v[sel][:, None])
        windows += core.pop_windows()
    late = int(T0 + 50 * P)
    core.add_accel_sample("a", late, 0.0, 0.0, 1.0)  # a clock jump back into an emitted window
    core.add_block(T0, FS, ["c", "d"], np.zeros((4, 3)))  # malformed
    core.add_accel_sample("zz", T0 + n * P, 0.0, 0.0, 9.8)  # a topic of no sensor
    windows += core.flush()

    def about(d, ch):
        return f"(sensor {ch})" in d.source or d.source.startswith(f"accel/{ch}.")

    def window_at(t):
        return next(w for w in windows if w.start_ns <= t < w.end_ns)

    flag_of = {"nan": SampleFlag.NAN, "spike": SampleFlag.SPIKE, "clipped": SampleFlag.CLIPPED,
               "duplicate_stamp": SampleFlag.DUPLICATE_STAMP, "out_of_order": SampleFlag.OUT_OF_ORDER}
    for kind, ch, t, win in faults:
        found = [d for d in core.diagnostics if d.code == kind and about(d, ch)]
        assert found, (kind, ch)
        w0 = T0 + win * W5 * P
        if kind in ("duplicate_stamp", "unsnappable", "gap"):
            assert t in [d.stamp_ns for d in found], (kind, ch)  # the stamp of the fault itself
        elif kind != "out_of_order":  # window faults are stamped with the start of their window
            assert any(w0 <= d.stamp_ns <= t < w0 + W5 * P for d in found), (kind, ch)
        c = chans.index(ch)
        if kind == "dead_channel":
            assert window_at(w0).channel_status[c] == "dead"
        elif kind in flag_of:
            w = window_at(t)
            row = (t - w.start_ns) // P
            assert w.flags is not None and w.flags[row, c] & flag_of[kind], (kind, ch)
        else:  # the grid point of an unsnappable stamp or of a gap is empty: the window splits there
            assert not any(w.start_ns <= t < w.end_ns for w in windows), (kind, ch)
        # no other channel is blamed for a fault that only one has
        others = [d for d in core.diagnostics if d.code == kind and d.stamp_ns is not None
                  and w0 <= d.stamp_ns < w0 + W5 * P and not about(d, ch)]
        assert not others, (kind, ch, others)
    assert any(d.code == "late_sample" and d.stamp_ns == late and about(d, "a") for d in core.diagnostics)
    assert any(d.code == "rejected" and d.source == "accel_block" for d in core.diagnostics)
    assert any(d.code == "unknown_topic" and d.source == "accel/zz" for d in core.diagnostics)
    # accepted data: nothing lost, nothing moved
    assert _accounted(core)
    assert core.stats.samples_not_windowed["late"] == 1
    for w in windows:
        k = (w.stamps_ns() - T0) // P
        for c, ch in enumerate(chans):
            missing = np.zeros(w.n_samples, bool) if w.flags is None else (w.flags[:, c] & SampleFlag.MISSING) != 0
            assert np.array_equal(w.samples[~missing, c], truth[ch][k[~missing]], equal_nan=True)


@pytest.mark.parametrize("ppm", [-1000.0, 300.0, 1500.0])
def test_grid_follows_a_drifting_clock(ppm):
    """A sensor clock 0.03-0.15 % off the nominal 200 Hz (the rate still rounds to 200 Hz) drifts by
    many periods over a long window; the grid follows it and every sample is placed, in order."""
    rng = np.random.default_rng(int(abs(ppm)))
    n = int(150 * FS)
    period = P * (1 - ppm * 1e-6)  # stamps of a clock running ppm fast
    base = T0 + np.round(np.arange(n) * period).astype(np.int64)
    chans = ["a", "b", "c"]
    core = offline(chans, window_s=60.0)
    xs = {}
    for c in chans:
        t = base + rng.integers(-int(0.15 * P), int(0.15 * P), n)
        t[0] = base[0]
        xs[c] = rng.standard_normal(n)
        core.add_accel(c, t, z3(xs[c]))
    ws = core.flush()
    assert [w.n_samples for w in ws] == [12000, 12000, 6000]
    for j, c in enumerate(chans):
        assert np.array_equal(np.concatenate([w.samples[:, j] for w in ws]), xs[c])
    assert all(w.flags is None for w in ws)
    assert ws[1].sample_rate_hz == pytest.approx(FS * (1 + ppm * 1e-6), rel=2e-5)
    assert ws[1].start_ns == pytest.approx(base[12000], abs=0.2 * P)
    assert "clock_drift" in codes(core) and not ({"gap", "unsnappable"} & codes(core))


def test_imu_in_g_found_from_the_gravity_magnitude():
    rng = np.random.default_rng(41)
    n = int(10 * FS)
    t = T0 + np.arange(n) * P
    tilt = np.array([0.6, 0.0, 0.8])  # mounted tilted: gravity split over x and z
    core = IngestCore(ChannelMap.simple({"h": "y"}), IngestConfig(window_s=10.0, max_latency_s=float("inf")))
    core.add_accel("h", t, tilt + 0.002 * rng.standard_normal((n, 3)))  # values in g
    (w,) = core.flush()
    diags = [d for d in core.diagnostics if d.code == "units"]
    assert diags and "look" in diags[0].message and diags[0].source == "accel/h"
    assert np.allclose(w.samples[:, 0], 0.0, atol=0.02)  # y axis, not rescaled
    ok = IngestCore(ChannelMap.simple({"h": "y"}), IngestConfig(window_s=10.0, max_latency_s=float("inf")))
    ok.add_accel("h", t, 9.80665 * tilt + 0.02 * rng.standard_normal((n, 3)))
    ok.flush()
    assert "units" not in codes(ok)


def test_channel_at_another_rate_is_dropped_not_shredding_the_window():
    rng = np.random.default_rng(51)
    n = int(20 * FS)
    core = offline(["a", "b", "slow"], window_s=10.0)
    core.add_accel("a", T0 + np.arange(n) * P, z3(rng.standard_normal(n)))
    core.add_accel("b", T0 + np.arange(n) * P, z3(rng.standard_normal(n)))
    xs = rng.standard_normal(n // 2)
    core.add_accel("slow", T0 + np.arange(n // 2) * 2 * P, z3(xs))  # a 100 Hz sensor
    ws = core.flush()
    assert [w.n_samples for w in ws] == [2000, 2000]
    assert all(w.channel_status[2] == "dropped" for w in ws)
    assert np.array_equal(ws[0].samples[::2, 2], xs[:1000])  # its samples are kept where they are
    assert np.isnan(ws[0].samples[1::2, 2]).all()
    assert any(d.code == "rate_mismatch" and "accel/slow" in d.source for d in core.diagnostics)


def test_a_fault_that_goes_on_is_reported_in_every_window():
    rng = np.random.default_rng(61)
    n = int(40 * FS)
    x = rng.standard_normal(n)
    x[::100] = np.nan  # 20 NaNs in each 10 s window
    core = offline(["a"], window_s=10.0, max_repeats=2)
    core.add_accel("a", T0 + np.arange(n) * P, z3(x))
    ws = core.flush()
    nan_diags = [d for d in core.diagnostics if d.code == "nan"]
    assert len(ws) == 4 and len(nan_diags) == 4 and all(d.count == 20 for d in nan_diags)
    assert sum(core.diagnostic_counts[k] for k in core.diagnostic_counts if k[0] == "nan") == 80
    core.add_accel_sample("zz", T0, 0.0, 0.0, 1.0)
    core.add_accel_sample("zz", T0 + P, 0.0, 0.0, 1.0)
    assert sum(d.code == "unknown_topic" for d in core.diagnostics) == 1


@pytest.mark.parametrize("seed", range(5))
def test_streaming_with_delayed_topics_equals_offline(seed):
    """Messages of different topics arrive out of step (each delayed by up to 0.4 s, a pause and a
    gap in the stream): a live core with max_latency_s = 1 cuts the same windows as offline."""
    rng = np.random.default_rng(500 + seed)
    keep = np.ones(int(50 * FS), bool)
    keep[int(18 * FS):int(19.5 * FS)] = False  # a 1.5 s pause: burst boundary
    keep[int(31 * FS):int(31.2 * FS)] = False  # a 0.2 s gap: window split
    k = np.flatnonzero(keep)
    grid = T0 + k * P
    data = {c: rng.standard_normal((k.size, 3)) for c in ("a", "b")}
    stamps = {"a": grid, "b": grid + rng.integers(-P // 4, P // 4, k.size)}
    stamps["b"][0] = grid[0] + 1
    block = rng.standard_normal((k.size, 1))
    events = []  # (arrival, kind, payload)
    for c in ("a", "b"):
        delay = rng.uniform(0, 0.4e9)
        for i in range(k.size):
            events.append((int(stamps[c][i] + delay), 0, (c, int(stamps[c][i]), *data[c][i])))
    for j in range(0, k.size, 40):  # 0.2 s blocks of a DAQ channel (no block spans the gaps)
        seg = slice(j, min(j + 40, k.size))
        if k[seg.stop - 1] - k[j] != seg.stop - 1 - j:
            continue
        events.append((int(grid[seg.stop - 1]) + int(0.05e9), 1, (int(grid[j]), block[seg])))
    events.sort(key=lambda e: e[0])
    cmap = ChannelMap([ChannelSource("a", "a", "z"), ChannelSource("b", "b", "z"),
                       ChannelSource("d", None, "z", "d")])
    live = IngestCore(cmap, IngestConfig(window_s=5.0, max_latency_s=1.0))
    off = IngestCore(cmap, IngestConfig(window_s=5.0, max_latency_s=float("inf")))
    got = []
    for _, kind, payload in events:
        for core in (live, off):
            if kind == 0:
                core.add_accel_sample(*payload)
            else:
                core.add_block(payload[0], FS, ["d"], payload[1])
        got += live.pop_windows()
    assert got, "windows come out while streaming"
    got += live.flush()
    ref = off.flush()
    assert [w.start_ns for w in got] == [w.start_ns for w in ref]
    assert [w.n_samples for w in got] == [w.n_samples for w in ref]
    for a, b in zip(got, ref, strict=True):
        assert np.array_equal(a.samples, b.samples, equal_nan=True)
    starts = [(w.start_ns - T0) / 1e9 for w in ref]
    assert any(abs(s - 19.5) < 0.01 for s in starts)  # the second burst is counted from its start
