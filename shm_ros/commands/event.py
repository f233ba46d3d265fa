"""`shm-ros event BAG --structure S.yaml --out event.json [--plots DIR] [--window SECONDS] ...`.

How the modes move within each earthquake of a recording. The bag is read and windowed as by
``shm-ros identify``; every window the ingest flagged as an event (or every window with
``--all-windows``) is analysed by ``shm_ros.core.event_analysis.analyse_event``: short moving
windows (10 periods of the structure's first natural frequency by default) identified by
input-output SSI when the structure file declares an input sensor, else by SSI-cov; frequency and
damping against time and response amplitude of the identified modes nearest to the nominal model's
lowest ones (modes the model does not describe are kept apart); the strong-motion interval
(Arias intensity 5-95 % of the input, else of the response); and pre-event, strong-motion and
post-event estimates with standard deviations from the spread over sub-windows. Output: one record
per event (docs/interfaces.md §3, ``events``); ``--plots DIR`` adds one figure per event (input
acceleration, frequency against time and against amplitude).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any


def add_parser(sub: argparse._SubParsersAction) -> None:
    from shm_ros.commands.checks import add_overwrite, min_float
    from shm_ros.commands.options import add_options
    from shm_ros.core.event_analysis import EventConfig
    from shm_ros.core.ingest.config import MIN_WINDOW_S

    p = sub.add_parser("event", help="frequency and damping within each earthquake (moving-window SSI)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bag", help="rosbag2 bag (MCAP or sqlite3 directory)")
    p.add_argument("--structure", required=True, help="structure YAML (sensors, optional input)")
    p.add_argument("--out", required=True, help="output JSON file (one record per event; see --overwrite)")
    add_overwrite(p)
    p.add_argument("--window", type=min_float(MIN_WINDOW_S), default=600.0,
                   help="ingest window length, s (default 600)")
    p.add_argument("--plots", default=None, help="directory for one figure per event (PNG; new or empty)")
    p.add_argument("--all-windows", action="store_true",
                   help="analyse every window, not only those the ingest flagged as events")
    add_options(p.add_argument_group("within-event analysis (EventConfig)"), EventConfig)
    p.set_defaults(func=run)


def _model_frequencies(spec: Any, n_modes: int) -> list[float] | None:
    """The nominal model's lowest ``n_modes + 1`` natural frequencies (None when the model cannot be
    built)."""
    import numpy as np

    from shm_ros.core.models import build_model
    from shm_ros.errors import ShmError

    try:
        return [float(f) for f in build_model(spec).modes(n_modes=n_modes + 1).frequencies_hz]
    except (ShmError, NotImplementedError, ValueError, ArithmeticError, np.linalg.LinAlgError):
        return None  # no model of this kind: the record's own lowest modes are followed


def run(args: argparse.Namespace) -> int:
    from contextlib import ExitStack
    from dataclasses import asdict

    from shm_ros.commands.checks import Outputs, input_file, input_path, output_dir, output_file
    from shm_ros.commands.options import config_from_args
    from shm_ros.core.event_analysis import EventConfig
    from shm_ros.core.provenance import stamp_output
    from shm_ros.errors import InputError, NoWindowsError
    from shm_ros.io.modes_json import dump
    from shm_ros.io.recording import ingest_bag
    from shm_ros.io.structure import load_structure

    input_path(args.bag, "BAG")
    input_file(args.structure, "--structure")
    output_file(args.out, "--out", args.overwrite)
    if args.plots:
        output_dir(args.plots, "--plots", args.overwrite)
    spec = load_structure(args.structure)
    try:
        cfg = config_from_args(EventConfig, args).validate()
    except (TypeError, ValueError) as exc:
        raise InputError(f"event options: {exc}") from None
    res = ingest_bag(args.bag, spec, window_s=args.window)
    for d in res.mismatches:
        print(f"shm-ros event: {args.bag}: warning: {d.message}", file=sys.stderr)
    if not res.windows:
        raise NoWindowsError(f"{args.bag}: no window found (shm-ros ingest lists the diagnostics)")
    model_f = _model_frequencies(spec, cfg.n_modes)
    f1 = model_f[0] if model_f else None
    with ExitStack() as staged:  # the figures appear in --plots when every event is done
        plots = staged.enter_context(Outputs(args.plots)) if args.plots else None
        records, n_ok = _analyse_all(args, res.windows, cfg, model_f, plots)
    config = {"event": asdict(cfg), "window_s": args.window, "bag": str(args.bag), "structure": str(args.structure),
              "lowest_frequency_hz": f1, "model_frequencies_hz": model_f}
    out = dump(stamp_output({"events": records}, config), args.out)
    print(f"{len(records)} event windows ({n_ok} analysed) -> {out}")
    for r in records:
        for m in r.get("modes", []):
            mn = m.get("minimum")
            if mn:
                print(f"  {r['start']} mode {m['mode']}: {m['reference_frequency_hz']:.4g} Hz, lowest "
                      f"{mn['frequency_hz']:.4g} Hz ({100 * mn['drop']:.1f} % down) at {mn['time_s']:.1f} s")
    return 0 if (n_ok or not records) else 1


def _analyse_all(args: argparse.Namespace, windows: list, cfg: Any, model_f: list[float] | None,
                 plots: Path | None) -> tuple[list[dict[str, Any]], int]:
    import numpy as np

    from shm_ros.core.event_analysis import analyse_event
    from shm_ros.core.timeutil import ns_to_iso

    records: list[dict[str, Any]] = []
    n_ok = 0
    for w in windows:
        if not (w.is_event or args.all_windows):
            continue
        rec: dict[str, Any] = {"start": ns_to_iso(w.start_ns), "end": ns_to_iso(w.end_ns), "pga_m_s2": w.pga_m_s2}
        try:
            result = analyse_event(w, cfg, model_frequencies_hz=model_f)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            rec.update({"window_id": w.window_id, "error": str(exc)})
            print(f"shm-ros event: window {w.window_id}: {exc}", file=sys.stderr)
            records.append(rec)
            continue
        n_ok += 1
        rec.update(result.to_record())
        if plots is not None:
            from shm_ros.report.event import plot_event

            plot_event(result, plots / f"event_{len(records):05d}.png", f"{rec['start']}  {result.method}")
            rec["plot"] = str(Path(args.plots) / f"event_{len(records):05d}.png")
        records.append(rec)
    return records, n_ok
