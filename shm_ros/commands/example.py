"""`shm-ros example --out DIR`: the bundled example, end to end through the real node graph.

Simulates a short campaign of a three-span girder (truth model finer than the nominal one, daily
temperature cycle, traffic-like excitation) and replays the bag through ingest -> identify -> track
-> update (separate processes over DDS, with a recorder node; the stages overlap as data flows).
Writes ``modes.json``, ``tracked_modes.csv`` + ``tracking.json``, ``update/posterior.json`` +
``samples.npz``, the recorder's bag, and ``report.html`` / ``report.md`` with a section per stage
(every figure's numbers next to it in ``figures/``).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path
from typing import Any


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("example", help="run the bundled example end to end", description=__doc__)
    p.add_argument("--out", default="out/example", help="output folder (default out/example)")
    p.add_argument("--windows", type=int, default=12, help="number of windows (default 12)")
    p.add_argument("--window-s", type=float, default=300.0, help="window length in s (default 300)")
    p.add_argument("--seed", type=int, default=7)
    p.set_defaults(func=run)


def stage_settings(n_windows: int, out: Path) -> dict[str, dict[str, Any]]:
    """Node parameters of the example: track's reference and training periods and update's
    schedule scaled to a short campaign (one posterior, from every window)."""
    half = max(3, n_windows // 2)
    return {"identify": {},
            "track": {"reference_windows": half, "training_windows": half, "store": str(out / "track.sqlite")},
            "update": {"min_windows": n_windows, "min_new_windows": n_windows,
                       "output_dir": str(out / "update")}}


def run(args: argparse.Namespace) -> int:
    from shm_ros.core.simulate import named_scenario, simulate_campaign
    from shm_ros.io.campaign import print_progress, write_campaign
    from shm_ros.ros.graph_run import replay_through_graph

    if args.windows < 3:
        print("shm-ros example: --windows must be at least 3 (tracking needs a reference period)",
              file=sys.stderr)
        return 2
    out = Path(args.out)
    recording = out / "recording"
    for old in (recording, out / "update", out / "figures"):
        if old.exists():
            shutil.rmtree(old)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    print(f"[example] simulating {args.windows} windows of {args.window_s:.0f} s (girder, seed {args.seed})")
    scenario = named_scenario("girder")
    scenario.n_windows, scenario.window_s, scenario.seed = args.windows, args.window_s, args.seed
    files = write_campaign(simulate_campaign(scenario), recording, progress=print_progress(every=4))
    settings = stage_settings(args.windows, out)
    print(f"[example] replaying {files.bag} through ingest -> identify -> track -> update "
          "(separate processes, DDS)")
    graph = replay_through_graph(files.bag, files.structure, out, window_s=args.window_s,
                                 expected_windows=args.windows, identify=settings["identify"],
                                 track=settings["track"], update=settings["update"],
                                 log=lambda s: print(f"[example] {s}", flush=True))
    report, facts = write_outputs(out, graph, Path(files.structure), Path(files.truth), settings, args)
    facts["wall time"] = f"{time.monotonic() - t0:.0f} s"
    for k, v in facts.items():
        print(f"[example] {k}: {v}")
    print(f"[example] wrote {report}")
    ok = (graph.replay.lost == 0 and len(graph.estimates) == args.windows and graph.node_exit_code == 0
          and (out / "update" / "posterior.json").is_file())
    if not ok:
        print("[example] the graph did not deliver every stage's results; see the report's diagnostics",
              file=sys.stderr)
    return 0 if ok else 1


def write_outputs(out: Path, graph: Any, structure: Path, truth_path: Path, settings: dict[str, dict[str, Any]],
                  args: argparse.Namespace) -> tuple[Path, dict[str, Any]]:
    """The stage files and the report from what the graph published."""
    from shm_ros.core.identify import IdentifyConfig, identify_window_detailed
    from shm_ros.core.tracking import TrackingConfig, track
    from shm_ros.io.modes_json import write_modes_json
    from shm_ros.io.tables import write_tracked_modes
    from shm_ros.report.build import build_report
    from shm_ros.report.identify_summary import match_to_truth
    from shm_ros.report.inputs import DiagnosticRow, IdentifyInputs, IngestInputs, ReportInputs
    from shm_ros.report.load import ReportInputError, load_posterior

    seed = args.seed
    config = {"example": {"windows": args.windows, "window_s": args.window_s, "seed": seed}, "nodes": settings}
    write_modes_json(out / "modes.json", graph.estimates, config=config, seed=seed)
    # The track node published one row per window; the table and the report's tracking section
    # come from the same core over the same estimates (the online tracker equals the batch result).
    n_train = settings["track"]["training_windows"]
    tracking = None
    try:
        tracking = track(graph.estimates, TrackingConfig(
            reference_windows=settings["track"]["reference_windows"],
            training_fraction=min(1.0, n_train / max(len(graph.estimates), 1))))
        write_tracked_modes(out / "tracked_modes.csv", tracking.observations)
    except ValueError as exc:
        print(f"[example] tracking: {exc}", file=sys.stderr)
    posterior = None
    try:
        posterior = load_posterior(out / "update")
    except ReportInputError as exc:
        print(f"[example] no posterior: {exc}", file=sys.stderr)
    # stabilization diagrams of the first, middle and last window (the node's settings)
    windows = sorted(graph.windows, key=lambda w: w.start_ns)
    diagrams = {}
    for w in {id(w): w for w in (windows[:1] + windows[len(windows) // 2:][:1] + windows[-1:])}.values():
        try:
            diagrams[w.window_id] = identify_window_detailed(w, IdentifyConfig(spectrum=True)).diagram
        except (ValueError, ArithmeticError):
            pass
    truth = json.loads(truth_path.read_text())
    matches = match_to_truth(graph.estimates, truth)
    errors = sorted(abs(e) for m in matches for e in m.error_pct if e is not None)
    found = sum(f is not None for m in matches for f in m.found_hz)
    facts: dict[str, Any] = {
        "structure": structure.name,
        "recording": f"{args.windows} windows of {args.window_s:.0f} s, simulated (seed {seed})",
        "messages replayed": graph.replay.published,
        "messages lost": graph.replay.lost,
        "windows from ingest": len(graph.windows),
        "modal estimates from identify": len(graph.estimates),
        "tracked-mode rows from track": len(graph.tracked),
        "posteriors from update": len(graph.posteriors),
        "true modes found (first 4 per window)": f"{found}/{sum(len(m.true_hz) for m in matches)}",
        "median |frequency error|": f"{errors[len(errors) // 2]:.3f} %" if errors else "-",
        "graph wall time": f"{graph.wall_s:.0f} s",
    }
    inputs = ReportInputs(
        title=f"shm_ros example: {_structure_name(structure)}", facts=facts,
        ingest=IngestInputs.from_windows(windows, [DiagnosticRow.from_any(d) for d in graph.diagnostic_rows
                                                   if d["level"] != 0]),
        identify=IdentifyInputs(graph.estimates, diagrams, "ssi-cov"), truth=truth,
        tracking=tracking, posterior=posterior)
    files = build_report(inputs, out)
    return files.html, facts


def _structure_name(path: Path) -> str:
    from shm_ros.io.structure import load_structure

    return str(load_structure(path).name)
