"""The report in a real headless browser: built from a small simulated campaign taken through
ingest, identify, track and update (plus placeholder prediction/explain results), opened from disk
by Debian's chromium. The page must load with every section, log nothing to the console, be
self-contained (every image a data: URI), and every figure must have its numbers next to it.

The screenshot is kept in ``$SHM_TEST_ARTIFACTS`` (default ``out/test-artifacts/``).
"""

from __future__ import annotations

import base64
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from browser import Images, artefact_dir, page_errors, run_chromium

ROOT = Path(__file__).resolve().parents[1]
N_WINDOWS, WINDOW_S = 14, 30.0


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """A small simulated campaign on disk (bag, structure file, truth), with sensor faults so that
    the data-health section has something to show."""
    from shm_ros.core.simulate import FaultSpec, named_scenario, simulate_campaign
    from shm_ros.io.campaign import write_campaign

    faults = [FaultSpec("dead", window=4, sensor="s7", at_s=0.0, duration_s=WINDOW_S),
              FaultSpec("nan", window=8, sensor="s2", at_s=10.0, duration_s=3.0),
              FaultSpec("spike", window=2, sensor="s3", at_s=5.0, count=5, value=5.0)]
    sc = named_scenario("girder", n_windows=N_WINDOWS, window_s=WINDOW_S, seed=1, faults=faults,
                        temperature_period_s=10.0)
    return write_campaign(simulate_campaign(sc), tmp_path_factory.mktemp("campaign"))


@pytest.fixture(scope="module")
def report(campaign, tmp_path_factory):
    """Every stage in memory -> build_report."""
    from shm_ros.core.bayes.update import UpdateConfig, update
    from shm_ros.core.identify import IdentifyConfig, identify_window_detailed
    from shm_ros.core.models import build_model
    from shm_ros.core.tracking import TrackingConfig, track
    from shm_ros.io.recording import ingest_bag
    from shm_ros.io.structure import load_structure
    from shm_ros.report.build import build_report
    from shm_ros.report.inputs import (
        ExplainInputs,
        IdentifyInputs,
        IngestInputs,
        PredictionInputs,
        ReportInputs,
    )

    spec = load_structure(campaign.structure)
    ing = ingest_bag(campaign.bag, spec, window_s=WINDOW_S)
    assert len(ing.windows) >= N_WINDOWS - 1
    cfg = IdentifyConfig(max_order=30, uncertainty=False, spectrum=True)
    estimates, diagrams = [], {}
    for w in ing.windows:
        r = identify_window_detailed(w, cfg)
        estimates.append(r.estimate)
        diagrams[w.window_id] = r.diagram
    tracked = track(estimates, TrackingConfig(reference_windows=3, training_fraction=0.75))
    post = update(build_model(spec), tracked.observations,
                  UpdateConfig(n_steps=200, max_steps=200, evidence=False), priors=spec.parameters)
    inputs = ReportInputs(
        title="shm_ros report (test campaign)", facts={"structure": spec.name},
        ingest=IngestInputs.from_windows(ing.windows, ing.diagnostics, ing.dropped),
        identify=IdentifyInputs(estimates, diagrams), truth=json.loads(campaign.truth.read_text()),
        tracking=tracked, posterior=post,
        prediction=_prediction_inputs(PredictionInputs),
        explain=_explain_inputs(ExplainInputs, tracked))
    out = tmp_path_factory.mktemp("report")
    return build_report(inputs, out), tracked


def _prediction_inputs(cls):
    """One event's prediction.json entry and traces (the section draws them with their band)."""
    t = np.arange(400) / 50.0
    y = np.sin(2 * np.pi * 1.1 * t) * np.exp(-0.1 * t)
    chan = {"quantity": "acceleration", "measured": True, "mean": y, "lower": y - 0.1, "upper": y + 0.1,
            "nominal": 1.2 * y, "values": y + 0.02}
    payload = {"model": "updated", "summary": {"n_events": 1, "nrms_pct_median": 8.0, "nrms_pct_nominal_median": 21.0},
               "table3": [{"window_id": "e1", "accel_floor4": 8.0, "accel_floor4_nominal": 21.0}],
               "events": [{"window_id": "e1", "channels": [{"name": "f4", "measured": True, "nrms_pct": 8.0}]}]}
    return cls(payload, {"events": [{"window_id": "e1", "fs": 50.0, "strong_s": [1.0, 4.0],
                                     "channels": {"f4": chan}}]})


def _explain_inputs(cls, tracked):
    """A verdict with its series on the tracked table's windows (the section's figures need them)."""
    obs = tracked.observations
    f = obs.frequencies_hz
    r = np.log(f / np.nanmean(f, axis=0))
    verdict = {"mismatch": {"modes": list(obs.mode_numbers), "sensors": [], "covariates": {},
                            "summary": "frequencies scatter about their mean"},
               "missing_physics": [],
               "fit": {"before": {"frequency_rmse_pct": 0.5}, "after": {"frequency_rmse_pct": 0.5},
                       "held_out": {"before": {}, "after": {}}},
               "candidates": [{"name": "temperature_dependent_stiffness", "where": "EI", "form": "linear",
                               "log_evidence_gain": 1.0, "accepted": False, "reasons": ["below threshold"]}]}
    series = {"times_s": obs.times, "mode_numbers": obs.mode_numbers, "log_residual_before": r,
              "log_residual_after": r, "train": np.arange(obs.n_windows) % 4 != 3,
              "covariates": {k: v for k, v in obs.covariates.items()},
              "form": {"x": [0.0, 1.0], "y": [1.0, 1.0], "x_label": "x", "y_label": "factor"}}
    return cls(verdict, series)


def test_report_opens_in_chromium(report, tmp_path):
    from shm_ros.report.document import section_anchor
    from shm_ros.report.sections import builders

    files, _ = report
    # every stage was given (a roving campaign's section is for robots' multi-setup recordings only)
    expected = [b.key for b in builders() if b.key != "roving"]
    assert files.sections == expected, "every stage was given: every section must be there"
    shot = tmp_path / "report.png"
    r = run_chromium(files.html, tmp_path, f"--screenshot={shot}", "--window-size=1400,3000")
    assert r.returncode == 0, r.stderr[-3000:]
    assert shot.is_file() and shot.stat().st_size > 20_000, "no (or an empty) screenshot"
    errors = page_errors(r.stderr)
    art = artefact_dir()
    shutil.copy(shot, art / "report.png")
    shutil.copy(files.html, art / "report.html")
    assert not errors, "chromium reported problems with the page:\n" + "\n".join(errors)

    d = run_chromium(files.html, tmp_path, "--dump-dom")
    assert d.returncode == 0, d.stderr[-3000:]
    assert not page_errors(d.stderr), "\n".join(page_errors(d.stderr))
    dom = Images()
    dom.feed(d.stdout)
    missing = [k for k in expected if section_anchor(k) not in dom.ids]
    assert not missing, f"sections missing from the rendered page: {missing}"
    assert len(dom.srcs) == len(files.figures) > 0
    assert all(s.startswith("data:image/png;base64,") for s in dom.srcs), "an image is not embedded"
    for s in dom.srcs:
        assert base64.b64decode(s.split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n"
    assert not dom.external, f"external resources: {dom.external}"
    assert "http://" not in d.stdout and "https://" not in d.stdout


def test_console_check_catches_page_errors(tmp_path):
    """The console check can fail: a page with a script error is reported."""
    bad = tmp_path / "bad.html"
    bad.write_text("<!doctype html><title>x</title><h1>x</h1><script>undefined_function();</script>")
    r = run_chromium(bad, tmp_path, "--dump-dom")
    assert any("undefined_function" in line for line in page_errors(r.stderr)), r.stderr[-3000:]


def test_figures_have_their_numbers_and_markdown_links_resolve(report):
    files, tracked = report
    out = files.html.parent
    for f in files.figures:
        assert f.png.is_file() and f.png.parent == f.data.parent and f.png.stem == f.data.stem, f
        assert f.data.suffix in (".csv", ".json") and f.data.stat().st_size > 0, f
        if f.data.suffix == ".json":
            json.loads(f.data.read_text())  # strict JSON: no NaN
    names = {f.png.name for f in files.figures}
    assert {"ingest_coverage.png", "identify_frequencies.png", "identify_stabilization_1.png",
            "tracking_frequencies.png", "tracking_damping.png", "tracking_temperature.png",
            "tracking_novelty.png", "corner.png", "trace.png"} <= names
    rows = (out / "figures" / "tracking_frequencies.csv").read_text().splitlines()
    assert len(rows) == 1 + tracked.observations.n_windows
    got = np.array([[float(c) if c else np.nan for c in r.split(",")[2:]] for r in rows[1:]])
    np.testing.assert_allclose(got, tracked.observations.frequencies_hz, equal_nan=True)
    md = files.markdown.read_text()
    links = re.findall(r"\]\(([^)]+)\)", md)
    assert len([x for x in links if x.endswith(".png")]) == len(files.figures)
    broken = [x for x in links if not (out / x).is_file()]
    assert not broken, f"report.md links to missing files: {broken}"
    coverage = (out / "figures" / "ingest_coverage.csv").read_text()
    assert ",dead" in coverage, "the dead channel of window 4 is not in the coverage data"


def test_report_command_builds_from_command_outputs(campaign, tmp_path):
    """`shm-ros report` from the files ingest/identify/track/update write."""
    from shm_ros.cli import main

    s, o = campaign, tmp_path
    common = ["--structure", str(s.structure)]
    assert main(["ingest", str(s.bag), *common, "--out", str(o / "ingest"), "--window", str(WINDOW_S),
                 "--quiet"]) == 0
    assert main(["identify", str(s.bag), *common, "--out", str(o / "modes.json"), "--window", str(WINDOW_S),
                 "--max-order", "30", "--no-uncertainty"]) == 0
    assert main(["track", str(o / "modes.json"), "--out", str(o / "track"), "--reference-windows", "3",
                 "--training-fraction", "0.75", "--no-plot"]) == 0
    assert main(["update", *common, "--modes", str(o / "track" / "tracked_modes.csv"), "--out",
                 str(o / "update"), "--steps", "200", "--max-steps", "200", "--no-evidence", "--no-plots"]) == 0
    rep = o / "report"
    assert main(["report", "--out", str(rep), "--windows", str(o / "ingest"), "--modes", str(o / "modes.json"),
                 "--tracking", str(o / "track"), "--posterior", str(o / "update"), "--truth", str(s.truth),
                 "--diagrams", "1"]) == 0
    html = (rep / "report.html").read_text()
    for key in ("ingest", "identify", "tracking", "posterior"):
        assert f'id="section-{key}"' in html
    assert 'id="section-prediction"' not in html  # a stage that did not run has no section
    fig = rep / "figures"
    assert (fig / "identify_stabilization_1.png").is_file(), "diagram not recomputed from the windows' samples"
    assert (fig / "tracking_novelty.csv").is_file() and (fig / "posterior" / "corner.csv").is_file()
    assert main(["report", "--out", str(o / "bad"), "--modes", str(o / "missing.json")]) == 2


def test_report_package_does_not_import_ros():
    code = ("import sys, shm_ros.report.build, shm_ros.report.load, shm_ros.commands.report; "
            "from shm_ros.report.sections import builders; builders(); "
            "print(sorted(m for m in sys.modules if m.startswith('shm_ros.ros') or m.startswith('rclpy')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", out.stdout
