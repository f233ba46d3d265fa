"""Bags of `shm-ros simulate`: topics and stamps of docs/interfaces.md §1, bursts, faults, determinism, CLI."""

from __future__ import annotations

import hashlib
import json
from collections import defaultdict

import numpy as np
import pytest

from shm_ros.cli import main
from shm_ros.core.simulate import FaultSpec, named_scenario, simulate_campaign
from shm_ros.io.bags import read_messages, topic_kind
from shm_ros.io.campaign import write_campaign
from shm_ros.io.structure import load_structure


def _digest(folder):
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def _blocks(bag):
    out = []
    for m in read_messages(bag):
        if topic_kind(m.topic, m.msgtype) == ("block", ""):
            msg = m.decode()
            t = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            x = np.asarray(msg.samples).reshape(-1, len(msg.channel_names))
            out.append((t, list(msg.channel_names), msg.sample_rate_hz, x))
    return out


def test_same_seed_gives_identical_bags_and_other_seeds_other_noise(tmp_path):
    digests, blocks = [], []
    for k, seed in enumerate([5, 5, 6]):
        sc = named_scenario("girder", n_windows=2, window_s=20.0, seed=seed)
        files = write_campaign(simulate_campaign(sc), tmp_path / f"run{k}")
        digests.append(_digest(files.bag))
        blocks.append(np.vstack([b[3] for b in _blocks(files.bag)]))
    assert digests[0] == digests[1]
    assert digests[0] != digests[2]
    assert np.array_equal(blocks[0], blocks[1])
    a, b = blocks[0] - blocks[0].mean(0), blocks[2] - blocks[2].mean(0)
    assert a.shape == b.shape
    corr = [np.corrcoef(a[:, c], b[:, c])[0, 1] for c in range(a.shape[1])]
    assert max(abs(v) for v in corr) < 0.2  # independent noise and loads, not a shifted copy


def test_worker_processes_write_the_same_bytes(tmp_path):
    sc = named_scenario("girder", n_windows=4, window_s=5.0, seed=8)
    one = write_campaign(simulate_campaign(sc), tmp_path / "one", workers=1)
    two = write_campaign(simulate_campaign(sc), tmp_path / "two", workers=2)
    assert _digest(one.bag) == _digest(two.bag)


def test_accel_block_bag_follows_the_recording_layout(tmp_path):
    sc = named_scenario("girder", n_windows=3, window_s=30.0, seed=2)
    c = simulate_campaign(sc)
    files = write_campaign(c, tmp_path)
    spec = load_structure(files.structure)
    truth = json.loads(files.truth.read_text())
    blocks = _blocks(files.bag)
    assert {tuple(b[1]) for b in blocks} == {tuple(spec.sensor_ids)}
    assert {b[2] for b in blocks} == {100.0}
    stamps = np.concatenate([b[0] + np.arange(b[3].shape[0]) * 10**7 for b in blocks])
    x = np.vstack([b[3] for b in blocks])
    gaps = np.diff(stamps)
    bursts = np.split(np.arange(stamps.size), np.nonzero(gaps > 10**7)[0] + 1)
    assert len(bursts) == 3 and all(len(b) == 3000 for b in bursts)
    assert np.all(gaps[gaps > 10**7] > 10**9)  # pauses longer than 1 s: one burst = one window
    assert stamps[0] == 1709251200 * 10**9  # 2024-03-01T00:00:00Z
    # gravity (REP-145) plus a small offset on the vertical axis
    assert np.all(np.abs(x.mean(axis=0) - 9.80665) < 0.1)
    temps = [m for m in read_messages(files.bag) if topic_kind(m.topic, m.msgtype) is not None
             and topic_kind(m.topic, m.msgtype)[0] == "temperature"]
    assert len(temps) >= 2  # one per minute over ~1.5 min
    assert len(truth["windows"]) == 3
    for w, start in zip(truth["windows"], [stamps[b[0]] for b in bursts]):
        assert w["start_ns"] == start
        # six in-plane (vertical) modes, plus the lateral and torsion modes among them
        assert w["mode_families"].count("vertical") == 6 and len(w["mode_families"]) == len(w["frequencies_hz"])
        assert set(w["mode_shapes"]) == set(spec.sensor_ids)
    assert spec.name == sc.structure["name"] and spec.girder.elements_per_span == 10
    for w in truth["windows"]:  # real shapes scaled to a largest component of +1 (docs/interfaces.md §3)
        shapes = np.array([w["mode_shapes"][s] for s in spec.sensor_ids])
        assert np.allclose(np.max(shapes, axis=0), 1.0) and np.all(np.max(np.abs(shapes), axis=0) <= 1.0)
    import csv

    rows = list(csv.DictReader(files.truth_table.open()))
    assert len(rows) == 3 and rows[0]["time"] == truth["windows"][0]["start"]
    assert float(rows[2]["mode3_hz"]) == pytest.approx(truth["windows"][2]["frequencies_hz"][2], rel=1e-7)
    assert float(rows[1]["mode1_shape_s5"]) == pytest.approx(truth["windows"][1]["mode_shapes"]["s5"][0], abs=1e-6)
    assert float(rows[0]["temperature_c"]) == pytest.approx(truth["windows"][0]["temperature_measured_c"], abs=1e-4)


def test_imu_bag_in_sqlite3_with_faults(tmp_path):
    faults = [FaultSpec("dropout", sensor="s2", at_s=2.0, duration_s=1.0),
              FaultSpec("duplicate", sensor="s3", at_s=1.0, count=4),
              FaultSpec("clock_jump", sensor="s4", at_s=5.0, value=0.5),
              FaultSpec("spike", sensor="s5", at_s=1.0, count=3, value=8.0),
              FaultSpec("dead", sensor="s6"),
              FaultSpec("clipped", sensor="s7", value=0.3),
              FaultSpec("nan", sensor="s8", at_s=1.0, duration_s=0.5)]
    sc = named_scenario("girder", n_windows=1, window_s=10.0, seed=3, output="imu", storage="sqlite3",
                        faults=faults)
    files = write_campaign(simulate_campaign(sc), tmp_path)
    assert any(p.suffix == ".db3" for p in files.bag.iterdir())
    per = defaultdict(list)
    for m in read_messages(files.bag):
        kind = topic_kind(m.topic, m.msgtype)
        if kind and kind[0] == "imu":
            msg = m.decode()
            a = msg.linear_acceleration
            per[kind[1]].append((msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec, a.x, a.y, a.z))
    stamps = {k: np.array([r[0] for r in v], dtype=np.int64) for k, v in per.items()}
    arr = {k: np.array(v) for k, v in per.items()}
    assert set(arr) == {f"s{i}" for i in range(1, 10)}
    assert len(arr["s1"]) == 1000 and abs(arr["s1"][:, 3].mean() - 9.80665) < 0.1
    assert len(arr["s2"]) == 900  # one second dropped
    st = stamps["s3"]
    assert len(st) == 1004 and np.count_nonzero(np.diff(st) == 0) == 4
    jumps = np.diff(stamps["s4"])
    assert np.count_nonzero(jumps == 510_000_000) == 1
    z5 = arr["s5"][:, 3]
    assert np.count_nonzero(np.abs(z5 - np.median(z5)) > 7.0) == 3
    assert np.ptp(arr["s6"][:, 3]) == 0.0
    z7 = arr["s7"][:, 3]
    assert np.count_nonzero(z7 == z7.max()) > 5 and np.count_nonzero(z7 == z7.min()) > 5
    assert np.count_nonzero(np.isnan(arr["s8"][:, 3])) == 50
    truth = json.loads(files.truth.read_text())
    assert [f["kind"] for f in truth["windows"][0]["faults"]] == [f.kind for f in faults]


def test_block_faults_hit_the_whole_acquisition_unit(tmp_path):
    faults = [FaultSpec("dropout", at_s=2.0, duration_s=1.5), FaultSpec("duplicate", at_s=8.0, count=1)]
    sc = named_scenario("building", n_windows=1, window_s=10.0, seed=3, faults=faults)
    files = write_campaign(simulate_campaign(sc), tmp_path)
    blocks = _blocks(files.bag)
    stamps = [b[0] for b in blocks]
    n = sum(b[3].shape[0] for b in blocks)
    dup = [b for k, b in enumerate(blocks) if b[0] in stamps[:k]]
    assert len(dup) == 1  # one block written twice, same stamp
    assert n == 1000 - 150 + dup[0][3].shape[0]  # 1.5 s dropped from every channel


def test_cli_writes_outputs_and_rejects_bad_options(tmp_path, capsys):
    out = tmp_path / "sim"
    rc = main(["simulate", "building-earthquake", "--out", str(out), "--duration", "40", "--seed", "9",
               "--effects", "damper@10s:model=kelvin_voigt", "--faults", "spike@0:f4", "--quiet"])
    assert rc == 0
    truth = json.loads((out / "truth.json").read_text())
    assert truth["seed"] == 9 and truth["provenance"]["random_seed"] == 9
    assert truth["hidden_effects"][0]["name"] == "damper_stiffness"
    assert truth["windows"][0]["event"]["pga_m_s2"] > 0
    assert "damper" not in (out / "structure.yaml").read_text()
    assert main(["simulate", "girder", "--out", str(tmp_path / "bad"), "--effects", "snowfall"]) == 2
    assert "unknown effect 'snowfall'" in capsys.readouterr().err
    assert main(["simulate", "girder", "--out", str(tmp_path / "bad2"), "--faults", "spike@x"]) == 2
    assert main(["simulate", "nowhere", "--out", str(tmp_path / "bad3")]) == 2


def test_scenario_file(tmp_path):
    f = tmp_path / "sc.yaml"
    f.write_text("scenario: girder\nn_windows: 2\nwindow_s: 5\nseed: 4\n"
                 "effects:\n  - {key: damage, at: 6s, factor: 0.8}\nfaults:\n  - {kind: dead, sensor: s1}\n")
    out = tmp_path / "o"
    assert main(["simulate", "--scenario-file", str(f), "--out", str(out), "--quiet"]) == 0
    truth = json.loads((out / "truth.json").read_text())
    assert truth["n_windows"] == 2 and truth["windows"][1]["effect_factors"] == {"EI:2": 0.8}
    assert truth["windows"][0]["effect_factors"] == {}


def test_earthquake_windows_carry_a_measured_base_input(tmp_path):
    sc = named_scenario("building-earthquake", n_windows=1, window_s=60.0, seed=1)
    w = simulate_campaign(sc).window(0)
    g = w.sensor_ids.index("g0")
    pga = w.truth["event"]["pga_m_s2"]
    assert w.truth["input_sensor"] == "g0"
    assert np.max(np.abs(w.accel[:, g])) == pytest.approx(pga, rel=0.05)
    f8 = w.sensor_ids.index("f8")
    assert np.max(np.abs(w.accel[:, f8])) > pga  # the building amplifies the ground motion


@pytest.mark.parametrize("fmt", ["block", "imu"])
def test_ingest_cuts_exactly_one_window_per_burst(tmp_path, fmt):
    """The project's own ingest reads the simulated bag: one window per burst, samples as recorded,
    temperature = mean of the temperature samples inside the window (docs/interfaces.md §1)."""
    from shm_ros.io.recording import ingest_bag

    sc = named_scenario("girder", n_windows=3, window_s=150.0, seed=4, output=fmt, unrelated_topics=True)
    c = simulate_campaign(sc)
    files = write_campaign(c, tmp_path)
    res = ingest_bag(files.bag, files.structure, window_s=150.0)
    truth = json.loads(files.truth.read_text())
    assert len(res.windows) == 3
    assert [t.split()[0] for t in res.ignored_topics] == ["/shm/daq/status"]
    for win, t in zip(res.windows, truth["windows"]):
        assert win.start_ns == t["start_ns"] and win.end_ns == t["end_ns"]
        assert win.samples.shape == (15000, 9)
        assert win.temperature_c == pytest.approx(t["temperature_measured_c"], abs=1e-3)
    rec = c.window(1).recording
    assert np.array_equal(res.windows[1].samples, rec.values[:, [rec.sensor_ids.index(s) for s in res.windows[1].channel_names]])


def test_truth_table_reads_as_a_tracked_modes_table(tmp_path):
    from shm_ros.io.tables import read_tracked_modes

    c = simulate_campaign(named_scenario("building", n_windows=2, window_s=90.0, seed=2))
    files = write_campaign(c, tmp_path)
    obs = read_tracked_modes(files.truth_table)
    truth = json.loads(files.truth.read_text())
    assert obs.frequencies_hz.shape == (2, max(len(w["frequencies_hz"]) for w in truth["windows"]))
    assert np.allclose(obs.frequencies_hz, [w["frequencies_hz"] for w in truth["windows"]], rtol=1e-7)
    assert obs.sensor_ids == c.sensor_ids


def test_bad_scenario_file_names_the_file_and_field(tmp_path, capsys):
    f = tmp_path / "bad.yaml"
    f.write_text("scenario: girder\nwindow_length: 5\n")
    assert main(["simulate", "--scenario-file", str(f), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert str(f) in err and "window_length" in err
    f.write_text("scenario: girder\nfaults:\n  - {kind: meltdown}\n")
    assert main(["simulate", "--scenario-file", str(f), "--out", str(tmp_path / "o2")]) == 2
    assert "faults[0]" in capsys.readouterr().err
    f.write_text("scenario: girder\nstructure: {name: x, kind: girder, girder: {spans: [10.0]}}\n")
    assert main(["simulate", "--scenario-file", str(f), "--out", str(tmp_path / "o3")]) == 2
    err = capsys.readouterr().err
    assert str(f) in err and "structure" in err and "sensors" in err


def test_n_story_building(tmp_path):
    assert main(["simulate", "building", "--floors", "12", "--duration", "20", "--out", str(tmp_path), "--quiet"]) == 0
    spec = load_structure(tmp_path / "structure.yaml")
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert spec.shear_building.n_floors == 12 and spec.sensor_ids == ["g0", "f1", "f6", "f9", "f12"]
    assert truth["truth_model"]["n_dof"] == 3 * 12  # x, y and twist of every floor
