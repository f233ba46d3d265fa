"""`shm-ros example --out DIR`: the bundled example, from recordings to verdict, in one report.

Reads the packaged ``main_job.yaml`` (``shm_ros/examples_data``, installed with the package; or
``--config``): two simulated campaigns with a known truth. ``--quick`` merges the file's ``quick:``
profile over it (a smoke-test size).

* girder: one winter day of a three-span girder whose deck stiffens below 0 degC (a concealed
  effect the structure file does not mention), replayed through ingest -> identify -> track ->
  update -> explain (+ recorder);
* building: an eight-story building with a measured ground input, ambient windows then earthquakes,
  replayed through ingest -> identify -> track -> update -> predict (+ recorder); the predict node
  waits for the posterior and predicts the floors' responses to the measured input. With
  ``calibrate_on_earlier_events`` (the packaged file: 2) the update node calibrates on the earlier
  earthquakes in the time domain, its modal posterior as the prior (:func:`calibration_files`), and
  the later ones are predicted.

Each graph is separate processes over DDS; the stages overlap as data flows. While the building's
graph runs, the bridge paper's Table 1 sweep (``shm-ros update --study``) runs on the girder's
tracked modes. Writes, under DIR: ``girder/`` and ``building/`` (recording, ``modes.json``,
``tracked_modes.csv``, ``update/posterior.json``, ``explain/verdict.json`` or
``prediction/prediction.json``, ``pipeline_bag`` = the run's output bag), ``girder/study/``, and
``report.html`` / ``report.md`` (a plain-words summary on top, a section per stage, the papers'
tables; every figure's numbers in ``figures/`` next to it) plus ``example.json`` (the run's facts).
"""

from __future__ import annotations

import argparse
import copy
import json
import multiprocessing
import shutil
import sys
import time
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

CONFIG = Path(__file__).resolve().parents[1] / "examples_data" / "main_job.yaml"


def add_parser(sub: argparse._SubParsersAction) -> None:
    from shm_ros.commands.checks import add_overwrite, min_float, nonneg_int, positive_int

    p = sub.add_parser("example", help="run the bundled example end to end", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="out/example", help="output folder (default out/example; new or empty, see "
                   "--overwrite)")
    add_overwrite(p)
    p.add_argument("--config", default=str(CONFIG), help="example file (default: the packaged main_job.yaml, "
                   "shm_ros/examples_data)")
    p.add_argument("--quick", action="store_true",
                   help="the file's quick profile: a small campaign and short samplers (a smoke test)")
    p.add_argument("--windows", type=positive_int, help="girder windows (default: the file's; the day is kept)")
    p.add_argument("--window-s", type=min_float(1.0), help="girder window length in s (default: the file's)")
    p.add_argument("--seed", type=nonneg_int, help="simulation seed of both parts (default: the file's)")
    p.set_defaults(func=run)


# -- configuration ------------------------------------------------------------------------------

def load_example(args: argparse.Namespace) -> dict[str, Any]:
    """The example file with the command line's overrides applied (the girder keeps its day)."""
    from shm_ros.io.structure import read_yaml

    doc = read_yaml(Path(args.config).read_text(encoding="utf-8"), args.config)
    if not isinstance(doc, dict):
        raise ValueError(f"{args.config}: must be a YAML mapping")
    quick = doc.pop("quick", None)
    if getattr(args, "quick", False):
        if not isinstance(quick, dict):
            raise ValueError(f"{args.config}: --quick needs a 'quick:' section")
        doc = merged(doc, quick)
    for part in ("girder", "building"):
        if not isinstance(doc.get(part), dict) or not isinstance(doc[part].get("scenario"), dict):
            raise ValueError(f"{args.config}: '{part}: scenario:' is required")
    g = doc["girder"]["scenario"]
    day = float(g.get("n_windows", 3)) * (float(g.get("window_s", 600.0)) + float(g.get("pause_s", 2.0)))
    if args.window_s:
        interval = float(g.get("window_s", 600.0)) + float(g.get("pause_s", 2.0))
        g["window_s"], g["pause_s"] = args.window_s, max(2.0, interval - args.window_s)
    if args.windows:
        g["n_windows"] = args.windows
        g["pause_s"] = max(2.0, day / args.windows - float(g["window_s"]))
    if args.seed is not None:
        for part in ("girder", "building"):
            doc[part]["scenario"]["seed"] = args.seed
    return doc


def merged(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    """``base`` with ``over`` merged in: mappings key by key, anything else replaced."""
    out = dict(base)
    for key, value in over.items():
        out[key] = merged(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out


def node_settings(part: dict[str, Any], n_windows: int, out: Path) -> dict[str, dict[str, Any]]:
    """The part's node parameters with what depends on the campaign's size and the output folder:
    track's reference and training periods (half the windows), update and explain on every window
    (one run each, when the last window has arrived), files under ``out``."""
    nodes = copy.deepcopy(part.get("nodes") or {})
    half = max(3, n_windows // 2)
    s: dict[str, dict[str, Any]] = {"identify": dict(nodes.get("identify") or {})}
    s["track"] = {"reference_windows": half, "training_windows": half, **(nodes.get("track") or {}),
                  "store": str(out / "track.sqlite")}
    s["update"] = {"min_windows": n_windows, "min_new_windows": n_windows, **(nodes.get("update") or {}),
                   "output_dir": str(out / "update")}
    if "explain" in nodes:
        s["explain"] = {"min_windows": n_windows, "min_new_windows": n_windows, **(nodes["explain"] or {}),
                        "output_dir": str(out / "explain")}
    if "predict" in nodes:
        s["predict"] = {"wait_for_posterior_s": 900.0, **(nodes["predict"] or {}),
                        "posterior": str(out / "update"), "output_dir": str(out / "prediction")}
    return s


# -- the run ------------------------------------------------------------------------------------

def _log(text: str) -> None:
    print(f"[example] {text}", flush=True)


def simulate_part(name: str, part: dict[str, Any], out: Path) -> Any:
    from shm_ros.core.simulate import simulate_campaign
    from shm_ros.core.simulate.scenario import scenario_from_dict
    from shm_ros.io.campaign import print_progress, write_campaign

    sc = scenario_from_dict(copy.deepcopy(part["scenario"]), source=f"example {name}")
    _log(f"{name}: simulating {sc.n_windows} windows of {sc.window_s:.0f} s every {sc.interval_s / 60:.0f} min "
         f"({sc.name}, seed {sc.seed}{', hidden: ' + ', '.join(e.key for e in sc.effects) if sc.effects else ''}"
         f"{f', {len(sc.earthquakes)} earthquake(s)' if sc.earthquakes else ''})")
    return write_campaign(simulate_campaign(sc), out / "recording", progress=print_progress(every=8)), sc


def run_part(name: str, files: Any, sc: Any, settings: dict[str, dict[str, Any]], out: Path) -> Any:
    from shm_ros.ros.graph_run import replay_through_graph

    stages = ["ingest", "identify", "track", "update", *[k for k in ("predict", "explain") if k in settings]]
    _log(f"{name}: replaying {files.bag} through {' -> '.join(stages)} (+ recorder; separate processes, DDS)")
    events = len(sc.earthquakes) + (sc.n_windows if sc.earthquake_every_window else 0)
    return replay_through_graph(files.bag, files.structure, out, window_s=sc.window_s,
                                expected_windows=sc.n_windows, identify=settings["identify"],
                                track=settings["track"], update=settings["update"],
                                predict=settings.get("predict"), explain=settings.get("explain"),
                                expected_predictions=events if "predict" in settings else None,
                                posterior_windows=settings["update"]["min_windows"]
                                if "calibration_windows" in (settings.get("predict") or {}) else None,
                                timeout_s=1800.0, log=lambda s: _log(f"{name}: {s}"))


def calibration_files(part: dict[str, Any], out: Path, sampler: dict[str, Any] | None = None) -> list[str]:
    """With ``predict: {calibrate_on_earlier_events: N}`` the part is calibrated as a monitoring
    system would be before its later earthquakes: the update node runs once, on the windows before
    the first later earthquake (the ambient windows' modes, and the first N earthquakes'), and the
    windows of the first N earthquakes, read from the recording, are written as window files
    (``out/calibration``): the update node, given them as ``calibration_windows`` (and ``sampler``
    plus the scenario's seed as its ``calibration.*`` parameters), calibrates on them in the time
    domain once its modal posterior exists (that posterior the prior; the result in
    ``out/update/time``), and the predict node, given that posterior and these windows, learns the
    model error out of sample (leave one event out) and predicts the later earthquakes.
    Returns the calibration events' window ids (also in ``out/calibration/events.json``)."""
    from shm_ros.errors import InputError
    from shm_ros.io.recording import windows_from_bag
    from shm_ros.io.structure import load_structure
    from shm_ros.io.window_files import save_window, window_filename

    pred = part["settings"].get("predict")
    n = int((pred or {}).pop("calibrate_on_earlier_events", 0) or 0)
    if not n:
        return []
    sc = part["scenario"]
    quakes = sorted(int(e["window"]) for e in sc.earthquakes)
    if n < 2 or len(quakes) <= n:
        raise InputError(f"predict: calibrate_on_earlier_events: {n} needs two or more, and fewer than the "
                         f"scenario's {len(quakes)} earthquakes (the later ones are predicted)")
    part["settings"]["update"]["min_windows"] = quakes[n]  # one run, before the first later earthquake
    windows, _ = windows_from_bag(part["files"].bag, load_structure(part["files"].structure), sc.window_s)
    (out / "calibration").mkdir(parents=True, exist_ok=True)
    paths = []
    for i in quakes[:n]:
        paths.append(str(out / "calibration" / window_filename(i, windows[i])))
        save_window(paths[-1], windows[i])
    pred["calibration_windows"] = paths
    upd = part["settings"]["update"]
    upd["calibration_windows"] = paths
    upd["calibration"] = {"seed": sc.seed, **(sampler or {})}
    pred["posterior"] = str(Path(upd["output_dir"]) / "time")
    ids = [windows[i].window_id for i in quakes[:n]]
    (out / "calibration" / "events.json").write_text(json.dumps(ids))
    return ids


def run(args: argparse.Namespace) -> int:
    from shm_ros.commands.checks import input_file, output_dir
    from shm_ros.commands.example_outputs import study_job, write_report, write_stage_files
    from shm_ros.errors import InputError, ShmError

    input_file(args.config, "--config")
    output_dir(args.out, "--out", args.overwrite)
    try:
        doc = load_example(args)
    except (OSError, ValueError) as exc:
        raise InputError(str(exc)) from None
    if int(doc["girder"]["scenario"].get("n_windows", 3)) < 6:
        raise InputError("the girder needs at least 6 windows (tracking's reference period)")
    out = Path(args.out)
    for old in ("girder", "building", "figures"):
        if (out / old).exists():
            shutil.rmtree(out / old)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    parts: dict[str, dict[str, Any]] = {}
    for name in ("girder", "building"):
        files, sc = simulate_part(name, doc[name], out / name)
        parts[name] = {"files": files, "scenario": sc,
                       "settings": node_settings(doc[name], sc.n_windows, out / name)}
    g = parts["girder"]
    g["graph"] = run_part("girder", g["files"], g["scenario"], g["settings"], out / "girder")
    g["stage"] = write_stage_files(out / "girder", g["graph"], g["settings"], doc)
    # the Table 1 sweep on the girder's tracked modes runs beside the building's graph
    pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"))
    study: Future | None = None
    if g["stage"].tracking is not None and doc["girder"].get("study") is not False:  # `study: false`: no sweep
        _log("girder: the bridge paper's Table 1 sweep (shm-ros update --study) starts on the tracked modes")
        study = pool.submit(study_job, g["stage"].tracking.observations, str(g["files"].structure),
                            dict(doc["girder"].get("study") or {}), str(out / "girder" / "study"))
    b = parts["building"]
    b["calibration"] = calibration_files(b, out / "building", doc["building"].get("calibration"))
    if b["calibration"]:
        n = len(b["calibration"])
        _log(f"building: the update node calibrates on {n} earlier earthquakes in the time domain (prior: its "
             f"modal posterior); the later {len(b['scenario'].earthquakes) - n} are predicted")
    b["graph"] = run_part("building", b["files"], b["scenario"], b["settings"], out / "building")
    b["stage"] = write_stage_files(out / "building", b["graph"], b["settings"], doc)
    study_rows = None
    if study is not None:
        try:
            study_rows = study.result()
        except (ShmError, ArithmeticError, ValueError, BrokenProcessPool) as exc:  # the report says it is missing
            print(f"[example] Table 1 sweep failed: {exc}", file=sys.stderr)
    pool.shutdown()
    report, facts, ok = write_report(out, parts, study_rows, t0)
    for k, v in facts.items():
        print(f"[example] {k}: {v}")
    print(f"[example] wrote {report}")
    if not ok:
        print("[example] the graph did not deliver every stage's results; see the report's notes", file=sys.stderr)
    return 0 if ok else 1
