"""`shm-ros explain --events BAG`: the time-domain path from a recording (docs/explain.md, Time domain).

The pipeline runs from a simulated earthquake bag (the building with a measured ground input) to
verdict.json, with the event windows ingest flags (docs/interfaces.md §1) as the records; the
science of the path is tested in test_explain_timedomain.py. Errors name the file: a structure
without a measured input; a recording without an event window gives a verdict with status no_windows."""

from __future__ import annotations

import json

import yaml

from shm_ros.cli import main
from shm_ros.io.recording import windows_from_bag
from shm_ros.io.structure import load_structure

WINDOW_S = 60.0


def test_explain_events_writes_a_time_domain_verdict(tmp_path, capsys):
    d = tmp_path / "quake"
    assert main(["simulate", "building-earthquake", "--out", str(d), "--windows", "4", "--window-s",
                 str(WINDOW_S), "--quiet", "--seed", "3"]) == 0
    s_path, bag = d / "structure.yaml", d / "bag"
    windows, _ = windows_from_bag(bag, load_structure(s_path), WINDOW_S)
    n_events = sum(w.is_event for w in windows)
    assert n_events >= 3
    out = tmp_path / "x"
    # per event only (the within-event fits are tested in test_explain_timedomain*.py): the options reach
    # the time-domain configuration
    assert main(["explain", "--structure", str(s_path), "--events", str(bag), "--window", str(WINDOW_S),
                 "--out", str(out), "--time-domain.resolutions", "per_event"]) == 0
    v = json.loads((out / "verdict.json").read_text())
    fit = v["fit"]
    assert fit["before"]["nrms_pct"] > 0 and "frequency_rmse_pct" not in fit["before"]
    tried = {c["name"] for c in v["candidates"]}
    assert {"amplitude_dependent_stiffness", "amplitude_dependent_damping"} <= tried
    assert not any(c["label"].endswith("within_event") for c in v["candidates"])
    assert f"calibrated on {n_events} events" in v["mismatch"]["summary"]
    assert "NRMS" in capsys.readouterr().out
    # the report draws the time-domain figures: per-event NRMS, the strongest event's record
    html = (out / "report.html").read_text()
    assert "explain_events_nrms" in html and "explain_events_record" in html
    series = json.loads((out / "explain_series.json").read_text())
    ex = series["events"]["example"]
    assert len(ex["measured"]) == len(ex["before"]) > 100

    # a structure without a measured input: exit 2, naming the file and the key
    plain = yaml.safe_load(s_path.read_text())
    plain.pop("input", None)
    plain.pop("inputs", None)
    p2 = tmp_path / "no_input.yaml"
    p2.write_text(yaml.safe_dump(plain))
    assert main(["explain", "--structure", str(p2), "--events", str(bag), "--window", str(WINDOW_S),
                 "--out", str(tmp_path / "y")]) == 2
    err = capsys.readouterr().err
    assert "no_input.yaml" in err and "input" in err

    # no event window (an ambient recording of the same building): a verdict that says so, status
    # no_windows, exit code 3
    calm = tmp_path / "calm"
    assert main(["simulate", "building", "--out", str(calm), "--windows", "1", "--window-s", "30", "--quiet"]) == 0
    assert main(["explain", "--structure", str(calm / "structure.yaml"), "--events", str(calm / "bag"),
                 "--out", str(tmp_path / "z")]) == 3
    v = json.loads((tmp_path / "z" / "verdict.json").read_text())
    assert v["status"] == "no_windows" and v["model_fits"] is None and v["missing_physics"] == []
    assert str(calm / "bag") in v["mismatch"]["summary"] and "event" in v["mismatch"]["summary"]
    assert "no_windows" in capsys.readouterr().out
