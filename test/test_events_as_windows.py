"""Earthquake records shorter than a window, years apart, at two sample rates: with the default
settings each record is one window of its own length at its own rate, and each is identified."""

from __future__ import annotations

import json

import numpy as np
import pytest

from shm_ros.cli import main
from shm_ros.core.ingest import ChannelMap, IngestConfig, IngestCore, Level
from shm_ros.core.simulate import named_scenario, simulate_campaign
from shm_ros.core.structure import structure_from_dict
from shm_ros.io.bags import BagWriter
from shm_ros.io.recording import ingest_bag
from shm_ros.io.structure import dump_structure

# (start, duration s, sample rate Hz): eight records years apart, one at twice the others' rate
RECORDS = [
    ("2016-02-03T04:05:06Z", 60.0, 100.0),
    ("2017-07-21T13:44:00Z", 85.0, 100.0),
    ("2018-11-30T23:59:30Z", 40.0, 100.0),
    ("2019-05-12T08:15:45Z", 72.0, 100.0),
    ("2020-09-01T17:30:00Z", 64.0, 200.0),
    ("2021-12-24T02:00:10Z", 90.0, 100.0),
    ("2023-03-15T11:11:11Z", 55.0, 100.0),
    ("2024-08-08T20:20:20Z", 80.0, 100.0),
]
FAST_UPDATE = ["--steps", "300", "--rhat", "1.05", "--ess", "300", "--n-live", "100"]


@pytest.fixture(scope="module")
def quake_bag(tmp_path_factory):
    """One bag of AccelBlocks (1 s each) with the eight records, the structure file and the true
    first frequency of each record."""
    d = tmp_path_factory.mktemp("quakes")
    bag = d / "bag"
    campaign = None
    f1_true = []
    with BagWriter(bag) as writer:
        for i, (start, dur, fs) in enumerate(RECORDS):
            sc = named_scenario("building-earthquake", n_windows=1, window_s=dur, fs=fs, start=start,
                                seed=10 + i, temperature_period_s=dur)
            campaign = simulate_campaign(sc)
            w = campaign.window(0)
            # the first x (in-plane) mode: the truth also lists the y and torsion modes among them
            f1_true.append(float(w.truth["frequencies_hz"][w.truth["mode_families"].index("x")]))
            rec, per = w.recording, int(fs)
            for b0 in range(0, rec.n, per):
                writer.accel_block("/site/accel_block", int(rec.stamps_ns[b0]), fs, list(rec.sensor_ids),
                                   rec.values[b0:b0 + per])
    assert campaign is not None
    structure = d / "structure.yaml"
    dump_structure(structure_from_dict(campaign.nominal_structure, source=str(structure)), structure)
    return bag, structure, f1_true


def _start_ns(iso: str) -> int:
    from datetime import datetime

    return int(datetime.fromisoformat(iso.replace("Z", "+00:00")).timestamp()) * 10**9


def test_default_ingest_gives_one_window_per_record_at_its_own_rate(quake_bag):
    bag, structure, f1_true = quake_bag
    res = ingest_bag(bag, structure)  # window_s 600 (the default): longer than every record
    assert len(res.windows) == len(RECORDS)
    for w, (start, dur, fs) in zip(res.windows, RECORDS, strict=True):
        assert w.start_ns == _start_ns(start)
        assert w.sample_rate_hz == fs and w.n_samples == int(dur * fs)
        assert w.is_event and w.pga_m_s2 > 0.1
        assert all(s == "ok" for s in w.channel_status or [])
        rms = w.covariates["rms_accel_m_s2"]
        assert 0.0 < rms < w.pga_m_s2
    # nothing dropped, silently or not
    assert not res.dropped
    assert res.stats.samples_windowed == res.stats.samples_in
    assert not [d for d in res.diagnostics if d.level >= Level.WARN]
    # the 200 Hz record is said to have its own rate (info), and the next one to go back
    changes = [d for d in res.diagnostics if d.code == "sample_rate" and "previous" in d.message]
    assert len(changes) == 2 and all(d.level == Level.OK for d in changes)
    assert "200 Hz" in changes[0].message and changes[0].stamp_ns == _start_ns(RECORDS[4][0])
    assert res.sample_rate_hz == 100.0 and res.sample_rates_hz == [100.0, 200.0]


def test_identify_and_update_with_defaults_use_every_record(quake_bag, tmp_path, capsys):
    bag, structure, f1_true = quake_bag
    out = tmp_path / "modes.json"
    assert main(["identify", str(bag), "--structure", str(structure), "--out", str(out)]) == 0
    records = json.loads(out.read_text())["windows"]
    assert [r["start"][:19] for r in records] == [s[:19] for s, _, _ in RECORDS]
    for r in records:
        assert "error" not in r and r["modes"], r.get("error")
        assert r["is_event"] and r["covariates"]["pga_m_s2"] == r["pga_m_s2"]
        assert r["covariates"]["rms_accel_m_s2"] > 0
    # the first mode of the building is found in every record, 100 Hz and 200 Hz alike (a record
    # of under a minute gives a rough estimate: 10 %); the nearest identified mode, since the x
    # sensors also see the building's first y-sway (10 % lower) and torsion modes
    err = np.array([min(abs(m["frequency_hz"] / f - 1) for m in r["modes"])
                    for r, f in zip(records, f1_true, strict=True)])
    assert np.all(err < 0.1) and err[4] < 0.03, err
    upd = tmp_path / "upd"
    assert main(["update", "--structure", str(structure), "--bag", str(bag), "--out", str(upd),
                 "--no-evidence", "--no-plots", *FAST_UPDATE]) == 0
    assert "not identified" not in capsys.readouterr().err
    assert (upd / "posterior.json").is_file()


T0 = 1_714_521_600_000_000_000  # 2024-05-01T00:00:00Z


def _noise(rng, n, c=2):
    return 0.01 * rng.standard_normal((n, c))


def test_short_burst_dropped_and_reported_longer_one_kept():
    rng = np.random.default_rng(3)
    core = IngestCore(ChannelMap.simple(["a", "b"]), IngestConfig(max_latency_s=float("inf")))
    core.add_block(T0, 100.0, ["a", "b"], _noise(rng, 1500))  # 15 s < min_window_s (20 s)
    t1 = T0 + 3600 * 10**9
    core.add_block(t1, 200.0, ["a", "b"], _noise(rng, 200 * 25))  # 25 s at another rate, an hour later
    (w,) = core.flush()
    assert (w.start_ns, w.sample_rate_hz, w.n_samples) == (t1, 200.0, 5000)
    (d,) = core.dropped
    assert (d.start_ns, d.n_samples) == (T0, 1500) and "min_window_s" in d.reason
    (diag,) = [x for x in core.diagnostics if x.code == "burst_dropped"]
    assert diag.level == Level.WARN and "15 s" in diag.message
    assert core.stats.samples_not_windowed["short_piece"] == 3000


def test_imu_bursts_fit_their_own_rates_and_a_gap_piece_follows_min_window():
    rng = np.random.default_rng(4)
    core = IngestCore(ChannelMap.simple(["a", "b"]), IngestConfig(max_latency_s=float("inf")))

    def burst(t0, fs, dur, skip=None):
        k = np.arange(int(dur * fs))
        if skip is not None:
            k = k[(k < skip[0] * fs) | (k >= skip[1] * fs)]
        t = t0 + np.round(k * 1e9 / fs).astype(np.int64)
        for ch in ("a", "b"):
            xyz = np.zeros((t.size, 3))
            xyz[:, 2] = rng.standard_normal(t.size)
            core.add_accel(ch, t, xyz)

    burst(T0, 100.0, 50.0)
    t2 = T0 + 86_400 * 10**9
    burst(t2, 250.0, 45.0, skip=(30.0, 30.5))  # a gap: 30 s kept, 14.5 s (< 20 s) dropped
    t3 = t2 + 86_400 * 10**9
    burst(t3, 100.0, 30.0)
    ws = core.flush()
    assert [(w.start_ns, w.sample_rate_hz, w.n_samples) for w in ws] == [
        (T0, 100.0, 5000), (t2, 250.0, 7500), (t3, 100.0, 3000)]
    (d,) = core.dropped
    assert d.start_ns == t2 + int(30.5 * 1e9) and "min_window_s" in d.reason
    rates = [x.message for x in core.diagnostics if x.code == "sample_rate" and "previous" in x.message]
    assert len(rates) == 2 and "250 Hz" in rates[0] and "100 Hz" in rates[1]


def test_a_rate_change_inside_a_burst_is_still_a_fault():
    core = IngestCore(ChannelMap.simple(["a"]), IngestConfig(window_s=1.0, max_latency_s=float("inf")))
    core.add_block(T0, 200.0, ["a"], np.arange(200.0)[:, None])
    core.add_block(T0 + 10**9, 250.0, ["a"], np.zeros((250, 1)))  # no pause before it
    ws = core.flush()
    assert [w.sample_rate_hz for w in ws] == [200.0]
    assert any(d.code == "rejected" and d.level == Level.ERROR and "inside a burst" in d.message
               for d in core.diagnostics)


def test_live_stream_emits_each_short_record_once_it_has_ended():
    """Streaming (settle_s, max_latency_s as in the node): a record shorter than a window comes out
    as soon as the pause after it is seen, at its own rate."""
    rng = np.random.default_rng(5)
    core = IngestCore(ChannelMap.simple(["a", "b"]), IngestConfig())
    for k in range(30):  # 30 s at 100 Hz, one block per second
        core.add_block(T0 + k * 10**9, 100.0, ["a", "b"], _noise(rng, 100))
    assert core.pop_windows() == []  # the record may still go on
    t1 = T0 + 600 * 10**9
    for k in range(25):  # ten minutes later, 25 s at 200 Hz
        core.add_block(t1 + k * 10**9, 200.0, ["a", "b"], _noise(rng, 200))
    (w,) = core.pop_windows()
    assert (w.start_ns, w.sample_rate_hz, w.n_samples) == (T0, 100.0, 3000)
    core.tick(t1 + 25 * 10**9 + 130 * 10**9)  # past the latency bound: the second record has ended
    (w2,) = core.pop_windows()
    assert (w2.start_ns, w2.sample_rate_hz, w2.n_samples) == (t1, 200.0, 5000)
    assert not core.dropped
