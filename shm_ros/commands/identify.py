"""`shm-ros identify BAG --structure S.yaml --out modes.json [--window SECONDS] [--method M]`.

Reads and windows the bag exactly as ``shm-ros ingest`` does, identifies every window with
``shm_ros.core.identify.identify_window`` and writes one record per window (contracts section 3):
start, end, temperature, and the modes sorted by frequency with damping, MPC, real mode shapes
labelled by sensor id, the spread across model orders and (SSI-cov, SSI-data) jackknife standard
deviations.
``--plots DIR`` saves one stabilization diagram per window. A window that cannot be identified is
written with an ``error`` and no modes; the other windows are not affected.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("identify", help="identify modes of every window of a recording (SSI)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bag", help="rosbag2 bag (MCAP or sqlite3 directory)")
    p.add_argument("--structure", required=True, help="structure YAML (sensors, optional input)")
    p.add_argument("--out", required=True, help="output JSON file (modes per window)")
    p.add_argument("--window", type=float, default=600.0, help="window length, s (default 600)")
    p.add_argument("--method", default="ssi-cov", choices=["ssi-cov", "ssi-data", "ssi-io"],
                   help="ssi-cov (default), ssi-data, or input-output ssi-io (needs `input:`)")
    p.add_argument("--weighting", default=None, choices=["pc", "upc", "cva"],
                   help="SSI-data weighting (default pc; upc = unweighted)")
    p.add_argument("--plots", default=None, help="directory for stabilization diagrams (PNG)")
    p.add_argument("--max-order", type=int, default=None, help="largest model order (default 60)")
    p.add_argument("--min-order", type=int, default=None, help="smallest model order (default 2)")
    p.add_argument("--order-step", type=int, default=None, help="model order step (default 1)")
    p.add_argument("--block-rows", type=int, default=None, help="block rows (default automatic)")
    p.add_argument("--references", default=None,
                   help="comma-separated reference sensor ids (SSI-cov/SSI-data; default all)")
    p.add_argument("--lowpass", type=float, default=None, help="low-pass corner, Hz (e.g. 20)")
    p.add_argument("--highpass", type=float, default=None, help="high-pass corner, Hz")
    p.add_argument("--decimate-to", type=float, default=None,
                   help="decimate (with anti-alias filter) to about this rate, Hz")
    p.add_argument("--detrend", default=None, choices=["none", "constant", "linear"],
                   help="offset/trend removal (default linear: gravity offsets and drift)")
    p.add_argument("--no-uncertainty", action="store_true", help="skip the jackknife uncertainty")
    p.add_argument("--config", default=None,
                   help="YAML/JSON file with IdentifyConfig fields (flags override it)")
    p.set_defaults(func=run)


def build_config(args: argparse.Namespace):
    from shm_ros.core.identify import IdentifyConfig

    base: dict[str, Any] = {}
    if args.config:
        import yaml

        try:
            base = yaml.safe_load(Path(args.config).read_text()) or {}
        except (OSError, yaml.YAMLError) as exc:
            raise ValueError(f"{args.config}: cannot read identify configuration: {exc}") from exc
        if not isinstance(base, dict):
            raise ValueError(f"{args.config}: identify configuration must be a mapping")
    try:
        cfg = IdentifyConfig.from_dict(base)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{args.config}: {exc}") from exc
    cfg.method = args.method
    for flag, field in (("max_order", "max_order"), ("min_order", "min_order"),
                        ("order_step", "order_step"), ("block_rows", "block_rows")):
        if getattr(args, flag) is not None:
            setattr(cfg, field, int(getattr(args, flag)))
    if args.references:
        cfg.reference_channels = [r.strip() for r in args.references.split(",") if r.strip()]
    if args.lowpass is not None:
        cfg.preprocess.lowpass_hz = args.lowpass
    if args.highpass is not None:
        cfg.preprocess.highpass_hz = args.highpass
    if args.decimate_to is not None:
        cfg.preprocess.target_rate_hz = args.decimate_to
    if args.detrend is not None:
        cfg.preprocess.detrend = args.detrend
    if args.no_uncertainty:
        cfg.uncertainty = False
    if args.weighting is not None:
        cfg.weighting = args.weighting
    try:
        return cfg.validate()
    except ValueError as exc:
        raise ValueError(f"{args.config or 'identify'}: {exc}") from exc


def _num(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(float(x)) else float(x)


def run(args: argparse.Namespace) -> int:
    from dataclasses import asdict

    from shm_ros.core.identify import identify_window_detailed
    from shm_ros.core.provenance import stamp_output
    from shm_ros.core.timeutil import ns_to_iso as iso_utc
    from shm_ros.io.modes_json import dump, estimate_record
    from shm_ros.io.recording import ingest_bag
    from shm_ros.io.structure import load_structure

    try:
        spec = load_structure(args.structure)
        cfg = build_config(args)
    except Exception as exc:  # StructureError / ValueError name the file and field
        print(f"shm-ros identify: {exc}", file=sys.stderr)
        return 2
    if cfg.method == "ssi-io" and getattr(spec, "input_sensor", None) is None:
        print(f"shm-ros identify: {args.structure}: --method ssi-io needs `input: {{sensor: ...}}` "
              "in the structure file", file=sys.stderr)
        return 2
    res = ingest_bag(args.bag, spec, window_s=args.window)
    for d in res.mismatches:  # a misspelt topic or sensor id: say so before anything else
        print(f"shm-ros identify: {args.bag}: warning: {d.message}", file=sys.stderr)
    for d in res.diagnostics:
        if d.level >= 2:
            print(str(d), file=sys.stderr)
    plots = Path(args.plots) if args.plots else None
    cfg.spectrum = plots is not None
    records = []
    n_ok = 0
    for w in res.windows:
        try:
            result = identify_window_detailed(w, cfg)
        except (ValueError, ArithmeticError, np_linalg_error()) as exc:
            records.append({"start": iso_utc(w.start_ns), "end": iso_utc(w.end_ns),
                            "temperature_c": _num(w.temperature_c), "window_id": w.window_id,
                            "modes": [], "error": str(exc)})
            print(f"shm-ros identify: window {w.window_id}: {exc}", file=sys.stderr)
            continue
        n_ok += 1
        rec = estimate_record(result.estimate, w)
        if result.notes or w.notes:
            rec["notes"] = list(w.notes) + list(result.notes)
        records.append(rec)
        if plots is not None:
            from shm_ros.report.stabilization import plot_stabilization

            name = f"stabilization_{len(records) - 1:05d}.png"
            plot_stabilization(result.diagram, plots / name,
                               f"{rec['start']}  {cfg.method}  ({len(rec['modes'])} modes)")
            rec["plot"] = str(plots / name)
    config = {"identify": asdict(cfg), "window_s": args.window, "bag": str(args.bag),
              "structure": str(args.structure)}
    out = dump(stamp_output({"windows": records}, config), args.out)
    n_modes = sum(len(r["modes"]) for r in records)
    print(f"{len(records)} windows ({n_ok} identified), {n_modes} modes -> {out}")
    return 0 if (n_ok or not res.windows) else 1


def np_linalg_error() -> type:
    import numpy as np

    return np.linalg.LinAlgError
