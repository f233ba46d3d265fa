"""The explain node on event series, over DDS: a simulated earthquake bag (the building with a measured
ground input) replayed through the real ingest, identify and explain nodes. The explain node keeps the
event windows ingest flags (docs/interfaces.md §1), explains them in the time domain once all have
arrived, publishes a ``Verdict`` of kind "events" with NRMS fields, writes ``output_dir/events``, and
agrees with :func:`explain_events` run offline on the same windows with the same options (the science
of the path is tested in test_explain_timedomain*.py; here, reduced options keep it short)."""

from __future__ import annotations

import json
import math

import pytest

from shm_ros.cli import main
from shm_ros.core.explain.timedomain import TimeDomainConfig, explain_events
from shm_ros.core.models import build_model
from shm_ros.core.predict import event_from_window
from shm_ros.io.recording import windows_from_bag
from shm_ros.io.structure import load_structure
from shm_ros.ros.graph_run import replay_through_graph

WINDOW_S = 60.0
TD = {"candidates": ["amplitude_stiffness", "amplitude_damping"], "resolutions": ["per_event"],
      "n_importance": 100}


def test_explain_node_explains_event_windows(tmp_path):
    d = tmp_path / "quake"
    assert main(["simulate", "building-earthquake", "--out", str(d), "--windows", "4", "--window-s",
                 str(WINDOW_S), "--quiet", "--seed", "3"]) == 0
    s_path, bag = d / "structure.yaml", d / "bag"
    spec = load_structure(s_path)
    windows, _ = windows_from_bag(bag, spec, WINDOW_S)
    events = [w for w in windows if w.is_event]
    assert len(events) >= 3
    out = tmp_path / "explain"
    run = replay_through_graph(bag, s_path, tmp_path / "graph", window_s=WINDOW_S, expected_windows=len(windows),
                               explain={"min_windows": 10 ** 6, "min_events": len(events), "output_dir": str(out),
                                        "time_domain": TD},
                               expected_events=len(events), timeout_s=420.0)
    assert run.replay.lost == 0 and len(run.windows) == len(windows)
    ev = [v for v in run.verdicts if v["kind"] == "events"]
    assert ev, f"no events Verdict published; diagnostics: {run.diagnostics[-5:]}"
    v = ev[-1]
    assert v["before_nrms_pct"] > 0 and math.isnan(v["before_frequency_rmse_pct"])
    assert f"calibrated on {len(events)} events" in v["summary"]
    doc = json.loads((out / "events" / "verdict.json").read_text())
    assert (out / "events" / "report.html").is_file()
    assert doc["fit"]["before"]["nrms_pct"] == pytest.approx(v["before_nrms_pct"])
    # the same science as offline on the same windows with the same options
    model = build_model(spec)
    ref = explain_events([event_from_window(w, model) for w in events], spec, TimeDomainConfig(**TD))
    assert [c["label"] for c in doc["candidates"]] == [c.label for c in ref.tried]
    for got, want in zip(doc["candidates"], ref.tried, strict=True):
        assert got["log_evidence_gain"] == pytest.approx(want.log_evidence_gain, rel=1e-6, abs=1e-6)
    assert [m["name"] for m in v["missing_physics"]] == [c.name for c in ref.missing_physics]
