"""The main job (README's first command) end to end through the real node graphs, at reduced size:
a girder day with a concealed freezing knee through ingest -> identify -> track -> update -> explain,
and a building with a measured ground input and five earthquakes through ingest -> identify -> track
-> update -> predict, ending in one report whose every section has a figure of this run with its
numbers next to it, that opens cleanly in a real browser. The building is calibrated as a monitoring
system would be before its later earthquakes: the update node runs once on the ambient windows and
the first two earthquakes' windows, the predict node waits for that posterior and learns the model
error from the first two earthquakes' records (time domain, leave one event out); the later three
(input PGAs 0.8 and 1.0 m/s², within the calibration's 0.6-1.2, and 1.5, beyond) are predicted.

Acceptance checked: every stage's files; identified frequencies against the simulator's truth (whose
model class is richer than the analysis model's: docs/simulator.md) within 1 % — per in-plane mode
the median over windows, and at least 90 % of all (window, mode) pairs of the first three in-plane
modes (single-window scatter of a 60-s window reaches 1 % now and then; the full-size command uses
longer windows); explain's top entry other than ``unmodelled_modes`` is the concealed effect
(``temperature_dependent_stiffness``). The example is one fixed seed (the README's), so these are
checks of that run, not statistics over seeds; explain's detection rate is tested over seeds in
test_explain_cases.py.

The building's predicted earthquakes (the packaged file's building, truth settings and seed, as the
README's command runs it), against their measurements, computed here from this run's recording and
prediction.json: median NRMS over events and measured channels <= max(25 %, oracle NRMS + 5 points),
the oracle being the model class's least-squares fit to the predicted events themselves
(test/predict_bands.py, as the predict acceptance computes it); strong-motion coverage of the 95 %
band (per event the median over the measured channels, the median over events) 0.85-0.99; the event
whose input PGA exceeds the calibration events' carries the out-of-calibration warning, the others do
not. Bands are checked on statistics over many campaigns in test_predict_bands.py; here, one fixed
seed, they are a check that the example shows what the method does.
"""

from __future__ import annotations

import base64
import json
import re
import shutil
import subprocess
import sys

import numpy as np
from browser import Images, artefact_dir, page_errors, run_chromium

from shm_ros.report.document import section_anchor

N_WINDOWS, WINDOW_S = 24, 60.0  # reduced size: the README's command runs the packaged main_job.yaml (48 x 120 s)
BUILDING_WINDOWS, BUILDING_WINDOW_S = 9, 120.0  # the packaged file's building, as it is
SECTIONS = {"Data health (ingest)": "ingest", "Identification": "identify", "Tracking": "tracking",
            "Posterior (model updating)": "posterior", "Prediction": "prediction",
            "Explanation (missing physics)": "explain", "The papers' tables": "papers"}


def _frequency_errors(part_dir) -> dict[int, list[float]]:
    """|f_identified / f_true - 1| in % per window for each of the first three in-plane true modes."""
    doc = json.loads((part_dir / "modes.json").read_text())
    truth = json.loads((part_dir / "recording" / "truth.json").read_text())
    family = truth["model_form"]["in_plane_family"]
    assert len(doc["windows"]) == len(truth["windows"])
    out: dict[int, list[float]] = {0: [], 1: [], 2: []}
    for w, tw in zip(doc["windows"], truth["windows"], strict=True):
        found = np.array([m["frequency_hz"] for m in w["modes"]])
        true = [f for f, g in zip(tw["frequencies_hz"], tw["mode_families"], strict=True) if g == family]
        for k, f in enumerate(true[:3]):
            out[k].append(float(np.min(np.abs(found / f - 1))) * 100)
    return out


def _building_scores(part_dir, pred: dict, calibrating: set[str]) -> dict[str, np.ndarray]:
    """The predicted (not calibrating) earthquakes' scores as test_predict_bands.py pools them: per
    event and measured channel the NRMS and the oracle's NRMS (events x channels), per event the
    median strong-motion coverage over its measured channels."""
    from predict_bands import _oracle

    from shm_ros.core.models import build_model
    from shm_ros.core.predict import PredictConfig, draws_from_posterior, event_from_window, predict_event
    from shm_ros.io.recording import windows_from_bag
    from shm_ros.io.structure import load_structure
    from shm_ros.report.load import load_posterior

    later = [e for e in pred["events"] if e["window_id"] not in calibrating]
    spec = load_structure(part_dir / "recording" / "structure.yaml")
    model = build_model(spec)
    windows, _ = windows_from_bag(part_dir / "recording" / "bag", spec, BUILDING_WINDOW_S)
    by_id = {w.window_id: w for w in windows}
    events = [event_from_window(by_id[e["window_id"]], model) for e in later]
    cfg = PredictConfig(n_draws=0, seed=0)
    theta_map = draws_from_posterior(load_posterior(part_dir / "update" / "time"), model, 0,
                                     np.random.default_rng(0), cfg.relative_error).theta_map
    od = _oracle(model, events, theta_map, cfg)
    out: dict[str, list] = {"nrms": [], "oracle": [], "coverage": []}
    for e, ev in zip(later, events, strict=True):
        measured = [c for c in e["channels"] if c["measured"]]
        oracle = predict_event(model, ev, od, cfg)
        out["nrms"].append([c["nrms_pct"] for c in measured])
        out["oracle"].append([oracle.channel(c["name"]).scores["nrms_pct"] for c in measured])
        out["coverage"].append(float(np.median([c["coverage_95_strong"] for c in measured])))
    return {k: np.asarray(v, float) for k, v in out.items()}


def test_example_runs_every_node_and_reports(tmp_path):
    out = tmp_path / "example"
    run = subprocess.run([sys.executable, "-m", "shm_ros.cli", "example", "--out", str(out),
                          "--windows", str(N_WINDOWS), "--window-s", str(WINDOW_S)],
                         capture_output=True, text=True, timeout=1200)
    supervisor = "\n".join(line for line in run.stdout.splitlines() if "[supervisor]" in line and "started" not in line)
    assert run.returncode == 0, supervisor + "\n" + run.stdout[-3000:] + run.stderr[-3000:]
    assert "messages replayed / lost" in run.stdout and not re.search(r"replayed / lost: \d+ / [1-9]", run.stdout)
    assert re.search(r"graph \[#+\] \d+/\d+ .*(ETA|done)", run.stdout + run.stderr), "no progress shown"

    # every stage's files, from this run
    g, b = out / "girder", out / "building"
    for part, n in ((g, N_WINDOWS), (b, BUILDING_WINDOWS)):
        doc = json.loads((part / "modes.json").read_text())
        assert doc["schema_version"] and doc["provenance"]["version"] and len(doc["windows"]) == n
        assert len((part / "tracked_modes.csv").read_text().splitlines()) == 1 + n
        post = json.loads((part / "update" / "posterior.json").read_text())
        assert post["parameters"] and (part / "update" / "samples.npz").stat().st_size > 1000
        assert (part / "pipeline_bag").is_dir()
        for k, errs in _frequency_errors(part).items():
            assert np.median(errs) < 1.0, (part.name, k, errs)
        pooled = np.concatenate(list(_frequency_errors(part).values()))
        assert np.mean(pooled < 1.0) >= 0.9, (part.name, np.sort(pooled)[-10:])
    pred = json.loads((b / "prediction" / "prediction.json").read_text())
    assert len(pred["events"]) == 5 and pred["model"] == "updated" and len(pred["table3"]) == 5
    calibrating = set(json.loads((b / "calibration" / "events.json").read_text()))
    assert len(calibrating) == 2 and "building: posteriors from update: 1 (last from 6 windows)" in run.stdout
    td = json.loads((b / "update" / "time" / "posterior.json").read_text())  # the update node's time-domain one
    assert td["diagnostics"]["likelihood"] == "time", td["diagnostics"]
    assert td["provenance"]["configuration"]["prior"] == str(b / "update" / "posterior.json"), td["provenance"]
    sc = _building_scores(b, pred, calibrating)
    nrms, oracle, coverage = (float(np.median(sc[k])) for k in ("nrms", "oracle", "coverage"))
    per_event = {k: np.round(np.median(sc[k], axis=1), 1).tolist() for k in ("nrms", "oracle")}
    print(f"building, predicted earthquakes: NRMS per event {per_event['nrms']} % (median over events and channels "
          f"{nrms:.1f} %), oracle {per_event['oracle']} % ({oracle:.1f} %), strong-motion coverage "
          f"{np.round(sc['coverage'], 3).tolist()} (median {coverage:.3f})")
    assert nrms <= max(25.0, oracle + 5.0), sc
    assert 0.85 <= coverage <= 0.99, sc
    cal_pga = max(e["input_pga_m_s2"] for e in pred["events"] if e["window_id"] in calibrating)
    for e in pred["events"]:
        if e["window_id"] not in calibrating:
            warned = any("above the strongest calibration event" in w for w in e["risk"]["warnings"])
            assert warned == (e["input_pga_m_s2"] > cal_pga), (e["window_id"], e["input_pga_m_s2"], cal_pga, e["risk"])
    verdict = json.loads((g / "explain" / "verdict.json").read_text())
    named = [m["name"] for m in verdict["missing_physics"] if m["name"] != "unmodelled_modes"]
    assert named and named[0] == "temperature_dependent_stiffness", verdict["missing_physics"]
    study = json.loads((g / "study" / "study.json").read_text())
    assert len(study["rows"]) == 7 and all(len(r["rmse"]) == len(study["rows"][0]["rmse"]) for r in study["rows"])

    # one report: a summary in plain words, a section per stage, each with a figure of this run and its data
    md = (out / "report.md").read_text()
    summary = md.split("## ", 2)[1]
    assert summary.startswith("Summary") and "What the model is missing: temperature dependent stiffness" in summary
    assert "Prediction:" in summary and "Hz" in summary and "°C" in summary
    later = [e["window_id"] for e in pred["events"] if e["window_id"] not in calibrating]
    assert all(f"building: predicted {w}" in md for w in later), "the report does not name each predicted event"
    assert "predicted out of sample: median NRMS" in md and "strong-motion coverage" in md
    parts = re.split(r"^## ", md, flags=re.M)[1:]
    by_title = {p.splitlines()[0].strip(): p for p in parts}
    assert set(SECTIONS) <= set(by_title), sorted(by_title)
    stamp = (g / "recording" / "truth.json").stat().st_mtime
    for title in SECTIONS:
        pngs = re.findall(r"\]\((figures/[^)]+\.png)\)", by_title[title])
        assert pngs, f"section {title!r} has no figure"
        for png in pngs:
            f = out / png
            assert f.is_file() and f.stat().st_mtime >= stamp
            assert any(f.with_suffix(s).is_file() for s in (".csv", ".json")), f"{png}: no data file"

    # ... that opens in a real browser without a console error, self-contained
    r = run_chromium(out / "report.html", tmp_path, f"--screenshot={tmp_path / 'shot.png'}",
                     "--window-size=1400,3000")
    assert r.returncode == 0 and not page_errors(r.stderr), "\n".join(page_errors(r.stderr)) or r.stderr[-2000:]
    shutil.copy(tmp_path / "shot.png", artefact_dir() / "example_report.png")
    d = run_chromium(out / "report.html", tmp_path, "--dump-dom")
    dom = Images()
    dom.feed(d.stdout)
    assert {section_anchor(k) for k in SECTIONS.values()} <= set(dom.ids), dom.ids
    assert dom.srcs and all(base64.b64decode(s.split(",", 1)[1])[:4] == b"\x89PNG" for s in dom.srcs)
    assert not dom.external
