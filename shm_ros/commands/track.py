"""`shm-ros track MODES.json --out DIR`: mode identities across windows, environment, novelty.

Reads the modal estimates written by ``shm-ros identify`` (docs/interfaces.md §3), tracks them with
``shm_ros.core.tracking.track`` and writes ``DIR/tracked_modes.csv`` (docs/interfaces.md §4, the
input of ``shm-ros update --modes``), ``DIR/normalised_modes.csv`` (the same table with the
frequencies at the training period's mean conditions), ``DIR/tracking.json`` (reference modes, the
environmental model per mode, novelty threshold, alarms with their modes; with provenance) and
``DIR/tracking.png``.

``shm-ros track --store DB --out DIR [--from T] [--to T]``: the windows of a history store (the
track node's, SQLite) in a time range -> the same two tables and ``DIR/alarms.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path
from typing import Any


def add_parser(sub: argparse._SubParsersAction) -> None:
    from shm_ros.commands.checks import add_overwrite
    from shm_ros.commands.options import add_options
    from shm_ros.core.tracking import TrackingConfig

    p = sub.add_parser("track", help="track modes across windows (identities, temperature, novelty)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("modes", nargs="?", help="modes JSON of `shm-ros identify`")
    p.add_argument("--out", required=True, help="output directory (new or empty; see --overwrite)")
    add_overwrite(p)
    p.add_argument("--store", help="history store (SQLite) to export from (without MODES.json)")
    p.add_argument("--from", dest="t_from", help="export windows starting at or after this time (ISO 8601)")
    p.add_argument("--to", dest="t_to", help="export windows starting before this time (ISO 8601)")
    p.add_argument("--structure", help="structure file whose FE modes seed the reference "
                   "(--reference-source model/both)")
    p.add_argument("--no-plot", action="store_true", help="skip tracking.png")
    add_options(p.add_argument_group("tracking (TrackingConfig; the track node's parameters of the "
                                     "same names)"), TrackingConfig)
    p.set_defaults(func=run)


def _num(v: float) -> float | None:
    return None if v is None or not math.isfinite(float(v)) else float(v)


def _ns(text: str | None) -> int | None:
    if text is None:
        return None
    from shm_ros.errors import InputError
    from shm_ros.io.tables import parse_time

    try:
        return int(round(parse_time(text) * 1e9))
    except (ValueError, OverflowError) as exc:
        raise InputError(f"--from/--to {text!r}: {exc}") from None


def export_store(args: argparse.Namespace) -> int:
    from shm_ros.commands.checks import Outputs
    from shm_ros.errors import InputError
    from shm_ros.io import jsonio
    from shm_ros.io.store import TrackStore
    from shm_ros.io.tables import write_tracked_modes

    lo, hi = _ns(args.t_from), _ns(args.t_to)
    with TrackStore(args.store, writer=False) as store:
        try:
            obs = store.observations(lo, hi)
            norm = store.observations(lo, hi, normalised=True)
        except ValueError as exc:
            raise InputError(str(exc)) from None
        alarms = [a for a in store.alarms() if (lo is None or a["start_ns"] >= lo)
                  and (hi is None or a["start_ns"] < hi)]
    out = Path(args.out)
    with Outputs(out) as stage:
        write_tracked_modes(stage / "tracked_modes.csv", obs)
        write_tracked_modes(stage / "normalised_modes.csv", norm)
        jsonio.dump({"store": str(args.store), "alarms": alarms}, stage / "alarms.json")
    print(f"{obs.n_windows} windows, {obs.n_modes} tracked modes, {len(alarms)} alarms from {args.store} -> {out}")
    return 0


def run(args: argparse.Namespace) -> int:
    from shm_ros.commands.checks import Outputs, input_file, output_dir
    from shm_ros.commands.options import config_from_args
    from shm_ros.core.provenance import stamp_output
    from shm_ros.core.tracking import TrackingConfig, track
    from shm_ros.errors import InputError, NoWindowsError
    from shm_ros.io import jsonio
    from shm_ros.io.modes_json import read_modes_json
    from shm_ros.io.tables import write_tracked_modes

    if args.modes is None and not args.store:
        raise InputError("give MODES.json, or --store DB to export")
    input_file(args.modes, "MODES")
    input_file(args.store, "--store", "store")
    input_file(args.structure, "--structure")
    output_dir(args.out, "--out", args.overwrite)
    if args.modes is None:
        return export_store(args)
    try:
        cfg = config_from_args(TrackingConfig, args)
    except (TypeError, ValueError) as exc:
        raise InputError(f"tracking options: {exc}") from None
    spec = None
    if args.structure:
        from shm_ros.io.structure import load_structure

        spec = load_structure(args.structure)
    try:
        estimates = read_modes_json(args.modes)
    except (OSError, KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
        raise InputError(f"{args.modes}: not a modes file of shm-ros identify: {type(exc).__name__}: {exc}") from None
    if not estimates:
        raise NoWindowsError(f"{args.modes}: holds no window")
    try:
        res = track(estimates, cfg, structure=spec)
    except ValueError as exc:
        raise InputError(f"{args.modes}: {exc}") from None
    out = Path(args.out)
    obs = res.observations
    payload: dict[str, Any] = {
        "reference_modes": [{"mode": r.number, "frequency_hz": r.frequency_hz,
                             "presence": r.presence,
                             "mode_shape": {s: _num(v) for s, v in zip(obs.sensor_ids, r.shape, strict=True)}}
                            for r in res.reference],
        "environment": [{k: (_num(v) if isinstance(v, float) else v)
                         for k, v in dataclasses.asdict(e).items()} for e in res.environment],
        "covariate": cfg.covariate,
        "born_modes": [{"mode": r.number, "window": r.born_window} for r in res.reference if r.source == "born"],
        "found_fraction": {str(n): float(v) for n, v in
                           zip(obs.mode_numbers, (obs.frequencies_hz == obs.frequencies_hz).mean(0),
                               strict=True)},
        "unassigned_modes": res.unassigned,
        "novelty": {"threshold": _num(res.novelty_threshold), "training_windows": res.n_training,
                    "alarms": int(res.novelty_alarm.sum()),
                    "alarm_windows": [w for w, a in zip(res.window_ids, res.novelty_alarm, strict=True) if a],
                    "alarm_modes": {w: m for w, m in zip(res.window_ids, res.alarm_modes, strict=True) if m},
                    "episodes": [{"first": res.window_ids[a], "last": res.window_ids[b]} for a, b in res.episodes],
                    "scores": [_num(v) for v in res.novelty_score]},
        "notes": res.notes,
    }
    doc = stamp_output(payload, {"track": dataclasses.asdict(cfg), "modes": str(args.modes)})
    with Outputs(out) as stage:
        write_tracked_modes(stage / "tracked_modes.csv", res.observations)
        write_tracked_modes(stage / "normalised_modes.csv", res.normalised_observations())
        jsonio.dump(doc, stage / "tracking.json")
        if not args.no_plot:
            from shm_ros.report.tracking import plot_tracking

            plot_tracking(res, stage / "tracking.png", cfg.covariate)
    found = ", ".join(f"mode {n} {100 * v:.0f} %" for n, v in payload["found_fraction"].items())
    print(f"{obs.n_windows} windows, {obs.n_modes} tracked modes ({found}); "
          f"{int(res.novelty_alarm.sum())} novelty alarms -> {out}")
    return 0
