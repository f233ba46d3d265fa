"""The bundled example's files and report, from what the node graphs published (``shm-ros example``)."""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

FIRST_IN_PLANE = 3  # in-plane modes per window checked against the truth


@dataclass
class StageFiles:
    """One part's results: batch tracking of the published estimates (the track node's rows equal
    it), the posterior, the truth, the identification's error against it, facts for the report."""

    tracking: Any = None
    posterior: Any = None
    truth: dict[str, Any] = field(default_factory=dict)
    errors_pct: list[float] = field(default_factory=list)  # |f_identified / f_true - 1|, first in-plane modes
    missed: int = 0  # first in-plane true modes with no identified mode within 5 %
    facts: dict[str, Any] = field(default_factory=dict)


def truth_errors(estimates: list[Any], truth: dict[str, Any]) -> tuple[list[float], int]:
    """Per window, the nearest identified frequency to each of the first in-plane true modes (the
    model's family; out-of-plane modes reach the sensors only through cross-axis sensitivity)."""
    family = (truth.get("model_form") or {}).get("in_plane_family")
    by_start = {int(w["start_ns"]): w for w in truth["windows"]}
    errors, missed = [], 0
    for e in estimates:
        tw = by_start.get(int(e.start_ns))
        if tw is None:
            continue
        true = [f for f, g in zip(tw["frequencies_hz"], tw["mode_families"], strict=True) if family in (None, g)]
        found = np.array([m.frequency_hz for m in e.modes], dtype=float)
        for f in true[:FIRST_IN_PLANE]:
            err = float(np.min(np.abs(found / f - 1.0))) * 100 if found.size else np.inf
            if err > 5.0:
                missed += 1
            else:
                errors.append(err)
    return errors, missed


def write_stage_files(out: Path, graph: Any, settings: dict[str, dict[str, Any]], doc: dict[str, Any]) -> StageFiles:
    """``modes.json`` and ``tracked_modes.csv`` of the estimates the graph published; the posterior."""
    from shm_ros.core.tracking import TrackingConfig, track
    from shm_ros.io.modes_json import write_modes_json
    from shm_ros.io.tables import write_tracked_modes
    from shm_ros.report.load import ReportInputError, load_posterior

    st = StageFiles()
    seed = doc.get("girder", {}).get("scenario", {}).get("seed")
    write_modes_json(out / "modes.json", graph.estimates, config={"example": doc, "nodes": settings}, seed=seed)
    n_ref = int(settings["track"]["reference_windows"])
    n_train = int(settings["track"]["training_windows"])
    try:
        st.tracking = track(graph.estimates, TrackingConfig(
            reference_windows=n_ref, training_fraction=min(1.0, n_train / max(len(graph.estimates), 1))))
        write_tracked_modes(out / "tracked_modes.csv", st.tracking.observations)
    except ValueError as exc:
        print(f"[example] tracking: {exc}", file=sys.stderr)
    try:
        st.posterior = load_posterior(out / "update")
    except ReportInputError as exc:
        print(f"[example] no posterior: {exc}", file=sys.stderr)
    st.truth = json.loads((out / "recording" / "truth.json").read_text())
    st.errors_pct, st.missed = truth_errors(graph.estimates, st.truth)
    e = sorted(st.errors_pct)
    st.facts = {
        "messages replayed / lost": f"{graph.replay.published} / {graph.replay.lost}",
        "windows: from ingest / identified / tracked": f"{len(graph.windows)} / {len(graph.estimates)} / "
                                                      f"{len(graph.tracked)}",
        f"first {FIRST_IN_PLANE} in-plane modes vs truth, |error| median / max":
            f"{e[len(e) // 2]:.2f} % / {e[-1]:.2f} % ({st.missed} not found)" if e else "-",
        "graph wall time": f"{graph.wall_s:.0f} s",
    }
    if graph.posteriors:
        last = graph.posteriors[-1]["n_windows"]
        st.facts["posteriors from update"] = f"{len(graph.posteriors)} (last from {last} windows)"
    if graph.predictions:
        st.facts["predictions from predict"] = str(len(graph.predictions))
    if graph.verdicts:
        names = [m["name"] for m in graph.verdicts[-1]["missing_physics"]]
        st.facts["verdict from explain"] = ", ".join(dict.fromkeys(names)) or "nothing missing"
    return st


def _posterior_line(folder: Path) -> str:
    """``: name MAP +- std, ...`` of the posterior in ``folder`` (empty without one)."""
    f = folder / "posterior.json"
    if not f.is_file():
        return ": no time-domain posterior"
    params = json.loads(f.read_text())["parameters"]
    return ": " + ", ".join(f"{k} {v['map']:.4f} ± {v['std']:.4f}" for k, v in params.items())


def later_events(payload: dict[str, Any], calibration: list[str]) -> dict[str, str]:
    """Per earthquake predicted out of sample (not among ``calibration``): the medians over its
    measured channels of NRMS and strong-motion coverage of the 95 % band, and its warnings."""
    out = {}
    for ev in payload.get("events", []):
        if ev["window_id"] in calibration:
            continue
        m = [c for c in ev["channels"] if c["measured"]]
        warn = "; ".join((ev.get("risk") or {}).get("warnings") or [])
        out[f"building: predicted {ev['window_id']} (input PGA {ev['input_pga_m_s2']:.2f} m/s²)"] = (
            f"NRMS {np.median([c['nrms_pct'] for c in m]):.1f} %, strong-motion coverage "
            f"{np.median([c['coverage_95_strong'] for c in m]):.3f}" + (f"; warning: {warn}" if warn else ""))
    return out


def study_job(obs: Any, structure: str, sampler: dict[str, Any], out_dir: str) -> dict[str, Any]:
    """The bridge paper's Table 1 sweep (``shm-ros update --study``) on tracked modes; writes
    ``study.json`` and ``study.txt`` into ``out_dir``. Runs in a worker process."""
    import os
    from dataclasses import fields

    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from shm_ros.core.bayes.study import bridge_study, format_table
    from shm_ros.core.bayes.update import UpdateConfig
    from shm_ros.core.models import build_model
    from shm_ros.core.priors import priors_from_specs
    from shm_ros.core.provenance import stamp_output
    from shm_ros.io import jsonio
    from shm_ros.io.structure import load_structure

    known = {f.name for f in fields(UpdateConfig)}
    cfg = UpdateConfig(**{k: v for k, v in sampler.items() if k in known})
    spec = load_structure(structure)
    t0 = time.monotonic()
    rows = bridge_study(build_model(spec), obs, priors_from_specs(spec.parameters), cfg)
    modes = rows[0].modes or list(obs.mode_numbers)
    payload = {"fitness_j": rows[0].fitness_j, "modes": modes, "rows": [r.to_dict() for r in rows],
               "wall_s": time.monotonic() - t0}
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    jsonio.dump(stamp_output(payload, {"sampler": sampler, "structure": structure}, cfg.seed), out / "study.json",
                indent=2)
    (out / "study.txt").write_text(format_table(rows, modes) + "\n")
    return payload


def write_report(out: Path, parts: dict[str, dict[str, Any]], study: dict[str, Any] | None,
                 t0: float) -> tuple[Path, dict[str, Any], bool]:
    """One report: the girder's ingest, identification, tracking, posterior and explanation, the
    building's prediction, the papers' tables; the run's facts in ``example.json``."""
    from shm_ros.core.identify import IdentifyConfig, identify_window_detailed
    from shm_ros.io import jsonio
    from shm_ros.report.build import build_report
    from shm_ros.report.inputs import (
        DiagnosticRow,
        ExplainInputs,
        IdentifyInputs,
        IngestInputs,
        PredictionInputs,
        ReportInputs,
    )

    g, b = parts["girder"], parts["building"]
    gg, bg = g["graph"], b["graph"]
    windows = sorted(gg.windows, key=lambda w: w.start_ns)
    diagrams = {}
    for w in {id(w): w for w in (windows[:1] + windows[len(windows) // 2:][:1] + windows[-1:])}.values():
        try:
            diagrams[w.window_id] = identify_window_detailed(w, IdentifyConfig(spectrum=True)).diagram
        except (ValueError, ArithmeticError):
            pass
    explain = prediction = None
    try:
        explain = ExplainInputs.from_files(out / "girder" / "explain")
    except (OSError, ValueError, KeyError) as exc:
        print(f"[example] no verdict: {exc}", file=sys.stderr)
    try:
        prediction = PredictionInputs.from_files(out / "building" / "prediction")
    except (OSError, ValueError, KeyError) as exc:
        print(f"[example] no prediction: {exc}", file=sys.stderr)
    gs, bs = g["scenario"], b["scenario"]
    facts: dict[str, Any] = {
        "girder": f"{gs.n_windows} windows of {gs.window_s:.0f} s every {gs.interval_s / 60:.0f} min, "
                  f"{len(g['stage'].truth.get('sensor_ids', []))} channels, simulated (seed {gs.seed}); "
                  f"nodes ingest, identify, track, update, explain",
        **{f"girder: {k}": v for k, v in g["stage"].facts.items()},
        "building": f"{bs.n_windows} windows of {bs.window_s:.0f} s, {len(bs.earthquakes)} with an earthquake, "
                    f"ground input g0, simulated (seed {bs.seed}); nodes ingest, identify, track, update, predict",
        **{f"building: {k}": v for k, v in b["stage"].facts.items()},
    }
    if prediction is not None and b.get("calibration"):
        facts["building: calibration earthquakes (time domain; prior: the ambient windows' modal posterior)"] = (
            ", ".join(b["calibration"]) + _posterior_line(out / "building" / "update" / "time"))
        facts.update(later_events(prediction.payload, b["calibration"]))
    if study is not None:
        facts["Table 1 sweep"] = f"{len(study['rows'])} configurations in {study['wall_s']:.0f} s"
    facts["wall time"] = f"{time.monotonic() - t0:.0f} s"
    inputs = ReportInputs(
        title="shm_ros example: a girder's winter day and a building's earthquakes", facts=facts,
        ingest=IngestInputs.from_windows(windows, [DiagnosticRow.from_any(d) for d in gg.diagnostic_rows
                                                   if d["level"] != 0]),
        identify=IdentifyInputs(gg.estimates, diagrams, "ssi-cov"), truth=g["stage"].truth,
        tracking=g["stage"].tracking, posterior=g["stage"].posterior, prediction=prediction, explain=explain,
        papers={"table1": study} if study is not None else None)
    files = build_report(inputs, out)
    jsonio.dump({"facts": facts, "sections": files.sections,
                 "identification_errors_pct": {"girder": g["stage"].errors_pct, "building": b["stage"].errors_pct},
                 "output_bags": {"girder": str(gg.output_bag), "building": str(bg.output_bag)}},
                out / "example.json", indent=1)
    n_events = len(bs.earthquakes)
    ok = (all(p["graph"].replay.lost == 0 and p["graph"].node_exit_code == 0
              and len(p["graph"].estimates) == p["scenario"].n_windows for p in parts.values())
          and (out / "girder" / "update" / "posterior.json").is_file() and explain is not None
          and prediction is not None and len(bg.predictions) >= n_events)
    return files.html, facts, ok
