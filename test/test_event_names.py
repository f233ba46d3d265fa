"""Windows called by their name: an earthquake is a window whose ground/input channel has a PGA of
at least 0.05 m/s^2 and whose own STA/LTA fires on that channel; every other triggered window is a
high-amplitude window (traffic, wind, works). Through the ingest of a recorded bag, its diagnostics
and the report's summary."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import yaml

from shm_ros.core.ingest import Level
from shm_ros.core.ingest.events import EventKind
from shm_ros.core.simulate import named_scenario, simulate_campaign
from shm_ros.core.simulate.excitation import earthquake
from shm_ros.core.structure import structure_from_dict
from shm_ros.io.bags import BagWriter
from shm_ros.io.recording import ingest_bag
from shm_ros.io.structure import dump_structure
from shm_ros.report.inputs import IngestInputs, ReportInputs
from shm_ros.report.summary import summary_sentences


def _ingest(tmp_path, campaign, structure: dict, edit=None):
    """Ingest the campaign's recordings (``edit(i, ids, values)`` may change a window's values)."""
    bag = tmp_path / "bag"
    with BagWriter(bag) as writer:
        for i in range(campaign.scenario.n_windows):
            rec = campaign.window(i).recording
            ids, vals = list(rec.sensor_ids), np.array(rec.values, dtype=float)
            if edit is not None:
                ids, vals = edit(i, ids, vals, campaign.scenario.fs)
            per = int(campaign.scenario.fs)
            for b0 in range(0, rec.n, per):
                writer.accel_block("/shm/accel_block", int(rec.stamps_ns[b0]), campaign.scenario.fs, ids,
                                   vals[b0:b0 + per])
    path = tmp_path / "structure.yaml"
    dump_structure(structure_from_dict(structure, source=str(path)), path)
    return ingest_bag(bag, path, window_s=campaign.scenario.window_s)


def _summary(res) -> str:
    x = ReportInputs(ingest=IngestInputs.from_windows(res.windows, res.diagnostics))
    return " ".join(summary_sentences(x))


def test_example_girder_traffic_is_no_earthquake(tmp_path):
    sc = yaml.safe_load(open(Path(__file__).resolve().parents[1] / "shm_ros" / "examples_data" / "main_job.yaml"))["girder"]["scenario"]
    fields = {k: v for k, v in sc.items() if k not in ("scenario", "effects")}
    fields.update(n_windows=6, window_s=120.0, pause_s=2.0, vehicles_per_hour=1200.0)
    camp = simulate_campaign(named_scenario("girder", **fields))
    res = _ingest(tmp_path, camp, camp.nominal_structure)
    loud = [w for w in res.windows if w.is_event]
    assert loud, "no traffic window triggered: nothing was named"
    assert all(w.event_kind == EventKind.HIGH_AMPLITUDE for w in loud)
    assert not any(w.event_kind == EventKind.EARTHQUAKE for w in res.windows)
    text = _summary(res)
    assert "earthquake (" not in text and "high-amplitude window" in text, text
    msgs = [d.message for d in res.diagnostics if d.code == "event"]
    assert msgs and all(m.startswith("high-amplitude window") for m in msgs)


def _gust(i, ids, vals, fs):
    """A wind gust on the upper floors in windows 1 and 3 (0.3 m/s^2 at the first mode, 8 s)."""
    if i in (1, 3):
        n = vals.shape[0]
        t = np.arange(n) / fs
        env = np.exp(-0.5 * ((t - t[n // 2]) / 3.0) ** 2)
        for k, s in enumerate(ids):
            if s != "g0":
                vals[:, k] += 0.3 * env * np.sin(2 * np.pi * 1.1 * t)
    return ids, vals


def test_building_with_ground_sensor_and_wind_has_no_earthquake(tmp_path):
    camp = simulate_campaign(named_scenario("building", n_windows=4, window_s=90.0, pause_s=2.0, fs=50.0, seed=3))
    res = _ingest(tmp_path, camp, camp.nominal_structure, _gust)
    assert [w.is_event for w in res.windows] == [False, True, False, True]
    assert all(w.input_channel == "g0" for w in res.windows)
    assert [w.event_kind for w in res.windows] == ["none", "high_amplitude", "none", "high_amplitude"]
    assert "high-amplitude window" in _summary(res) and "earthquake (" not in _summary(res)


def _ground_quake(i, ids, vals, fs):
    """A ground sensor at the first bearing: microtremor, and an earthquake in window 1 whose deck
    response (the ground motion, amplified) the vertical sensors read."""
    rng = np.random.default_rng(i)
    n = vals.shape[0]
    g = 2e-3 * rng.standard_normal(n)
    if i == 1:
        eq = earthquake(rng, n, fs, 20.0, 0.3)
        g = g + eq
        vals += 2.0 * eq[:, None]
    return [*ids, "g0"], np.column_stack([vals, g])


def test_girder_with_ground_sensor_names_its_earthquake(tmp_path):
    camp = simulate_campaign(named_scenario("girder", n_windows=3, window_s=90.0, pause_s=2.0, fs=50.0, seed=2,
                                            vehicles_per_hour=50.0))
    st = copy.deepcopy(camp.nominal_structure)
    st["sensors"].append({"id": "g0", "at": {"x": 0.0}, "direction": "vertical"})
    st["input"] = {"sensor": "g0", "kind": "base"}
    res = _ingest(tmp_path, camp, st, _ground_quake)
    kinds = [w.event_kind for w in res.windows]
    assert kinds[1] == "earthquake" and "earthquake" not in (kinds[0], kinds[2]), kinds
    assert "1 earthquake (" in _summary(res)
    quake = [d for d in res.diagnostics if d.code == "event" and d.level == Level.OK]
    assert any(d.message.startswith("earthquake in") and "input g0" in d.message for d in quake)
