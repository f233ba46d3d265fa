"""`shm-ros identify BAG --structure S.yaml --out modes.json [--window SECONDS] [--method M] ...`.

Reads and windows the bag exactly as ``shm-ros ingest`` does, identifies every window with
``shm_ros.core.identify.identify_window`` and writes one record per window (docs/interfaces.md §3):
start, end, temperature, and the modes sorted by frequency with damping, MPC, real mode shapes
labelled by sensor id, the spread across model orders and (SSI-cov, SSI-data) jackknife standard
deviations.
The default method ``auto`` is input-output SSI (``ssi-io``) when the structure file declares an
input sensor (``input: {sensor: ...}``) that the window carries, else output-only SSI-cov; each
record's ``method`` and the provenance's ``methods_used`` say which one ran.
The band of interest (from the structure's nominal model, else the spectrum) sets the decimation
and the block rows; each record's ``band`` and the provenance's ``bands_used`` say what was chosen
and why, each record's ``filters`` how many poles each filter removed.
``--plots DIR`` saves one stabilization diagram per window. A window that cannot be identified is
written with an ``error`` and no modes; the other windows are not affected.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

# older spellings of generated options, still accepted
ALIASES = {"reference_channels": ["--references"], "preprocess.lowpass_hz": ["--lowpass"],
           "preprocess.highpass_hz": ["--highpass"], "preprocess.target_rate_hz": ["--decimate-to"],
           "preprocess.detrend": ["--detrend"]}


def add_parser(sub: argparse._SubParsersAction) -> None:
    from shm_ros.commands.checks import add_overwrite, min_float
    from shm_ros.commands.options import add_options
    from shm_ros.core.identify import IdentifyConfig
    from shm_ros.core.ingest.config import MIN_WINDOW_S

    p = sub.add_parser("identify", help="identify modes of every window of a recording (SSI)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bag", help="rosbag2 bag (MCAP or sqlite3 directory)")
    p.add_argument("--structure", required=True, help="structure YAML (sensors, optional input)")
    p.add_argument("--out", required=True, help="output JSON file (modes per window; see --overwrite)")
    add_overwrite(p)
    p.add_argument("--window", type=min_float(MIN_WINDOW_S), default=600.0,
                   help="window length, s (default 600)")
    p.add_argument("--plots", default=None, help="directory for stabilization diagrams (PNG; new or empty)")
    p.add_argument("--config", default=None,
                   help="YAML/JSON file with IdentifyConfig fields (options given here override it)")
    add_options(p.add_argument_group("identification (IdentifyConfig; the identify node's "
                                     "parameters of the same names)"), IdentifyConfig, aliases=ALIASES)
    p.set_defaults(func=run)


def build_config(args: argparse.Namespace):
    from shm_ros.commands.options import config_from_args
    from shm_ros.core.identify import IdentifyConfig
    from shm_ros.errors import InputError

    base: dict[str, Any] = {}
    if args.config:
        from shm_ros.io.structure import read_yaml

        try:
            text = Path(args.config).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"{args.config}: cannot read identify configuration: {exc}") from None
        base = read_yaml(text, args.config) or {}
        if not isinstance(base, dict):
            raise InputError(f"{args.config}: identify configuration must be a mapping")
    try:
        cfg = config_from_args(IdentifyConfig, args, base=IdentifyConfig.from_dict(base))
        return cfg.validate()
    except (TypeError, ValueError) as exc:
        raise InputError(f"{args.config or 'identify'}: {exc}") from None


def _num(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(float(x)) else float(x)


def _methods_line(requested: str, used: dict[str, int], input_sensor: str | None) -> str:
    """E.g. ``method auto: ssi-io in 3 windows (input sensor g0)``."""
    runs = ", ".join(f"{m} in {n} window{'s' * (n != 1)}" for m, n in used.items())
    io = f" (input sensor {input_sensor})" if "ssi-io" in used else ""
    return f"method {requested}: {runs or 'no window identified'}{io}"


def run(args: argparse.Namespace) -> int:
    from contextlib import ExitStack
    from dataclasses import asdict

    from shm_ros.commands.checks import Outputs, input_file, input_path, output_dir, output_file
    from shm_ros.core.provenance import stamp_output
    from shm_ros.errors import InputError, NoWindowsError
    from shm_ros.io.modes_json import dump
    from shm_ros.io.recording import ingest_bag
    from shm_ros.io.structure import load_structure

    input_path(args.bag, "BAG")
    input_file(args.structure, "--structure")
    input_file(args.config, "--config")
    output_file(args.out, "--out", args.overwrite)
    if args.plots:
        output_dir(args.plots, "--plots", args.overwrite)
    spec = load_structure(args.structure)
    cfg = build_config(args)
    if spec.roving:  # a robot's roving sensors: setups from tf, merged (docs/interfaces.md section 8)
        from shm_ros.commands.roving import identify as identify_roving

        return identify_roving(args, spec, cfg)
    if cfg.method == "ssi-io" and getattr(spec, "input_sensor", None) is None:
        raise InputError(f"{args.structure}: --method ssi-io needs `input: {{sensor: ...}}` in the structure file")
    res = ingest_bag(args.bag, spec, window_s=args.window)
    for d in res.mismatches:  # a misspelt topic or sensor id: say so before anything else
        print(f"shm-ros identify: {args.bag}: warning: {d.message}", file=sys.stderr)
    for d in res.diagnostics:
        if d.level >= 2:
            print(str(d), file=sys.stderr)
    if not res.windows:
        raise NoWindowsError(f"{args.bag}: no window found (shm-ros ingest lists the diagnostics)")
    if not cfg.nominal_frequencies_hz:  # the band of interest from the nominal model (docs/identify.md)
        from shm_ros.core.band import band_frequencies

        cfg.nominal_frequencies_hz, why_not = band_frequencies(spec, cfg.band, cfg.band_modes)
        if why_not:
            print(f"shm-ros identify: {args.structure}: {why_not}", file=sys.stderr)
    with ExitStack() as staged:  # the diagrams appear in --plots when every window is done
        plots = staged.enter_context(Outputs(args.plots)) if args.plots else None
        records, n_ok, used, bands = _identify_all(res.windows, cfg, plots, args.plots)
    config = {"identify": asdict(cfg), "methods_used": used, "bands_used": bands, "window_s": args.window,
              "bag": str(args.bag), "structure": str(args.structure)}
    out = dump(stamp_output({"windows": records}, config), args.out)
    n_modes = sum(len(r["modes"]) for r in records)
    print(_methods_line(cfg.method, used, cfg.input_channel or getattr(spec, "input_sensor", None)))
    for text, n in bands.items():
        print(f"{text} in {n} window{'s' * (n != 1)}")
    print(f"{len(records)} windows ({n_ok} identified), {n_modes} modes -> {out}")
    return 0 if n_ok else 1


def _identify_all(windows: list, cfg: Any, plots: Path | None, plots_name: str | None
                  ) -> tuple[list[dict[str, Any]], int, dict[str, int], dict[str, int]]:
    """Every window identified: its records, how many succeeded, methods and bands used."""
    import numpy as np

    from shm_ros.core.identify import identify_window_detailed
    from shm_ros.core.progress import Progress
    from shm_ros.core.timeutil import ns_to_iso as iso_utc
    from shm_ros.io.modes_json import estimate_record

    cfg.spectrum = plots is not None
    records: list[dict[str, Any]] = []
    n_ok = 0
    used: dict[str, int] = {}  # method actually run (auto resolved) -> windows
    bands: dict[str, int] = {}  # band choice (describe()) -> windows
    progress = Progress("windows identified", every_s=2.0)
    for k, w in enumerate(windows):
        progress(k, len(windows))
        try:
            result = identify_window_detailed(w, cfg)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            records.append({"start": iso_utc(w.start_ns), "end": iso_utc(w.end_ns),
                            "temperature_c": _num(w.temperature_c), "window_id": w.window_id,
                            "modes": [], "error": str(exc)})
            print(f"shm-ros identify: window {w.window_id}: {exc}", file=sys.stderr)
            continue
        n_ok += 1
        used[result.estimate.method] = used.get(result.estimate.method, 0) + 1
        rec = estimate_record(result.estimate, w)
        if result.band is not None:
            rec["band"] = result.band.to_dict()
            bands[result.band.describe()] = bands.get(result.band.describe(), 0) + 1
        if result.filters is not None:
            rec["filters"] = result.filters.to_dict()
        if result.notes or w.notes:
            rec["notes"] = list(w.notes) + list(result.notes)
        records.append(rec)
        if plots is not None:
            from shm_ros.report.stabilization import plot_stabilization

            name = f"stabilization_{len(records) - 1:05d}.png"
            plot_stabilization(result.diagram, plots / name,
                               f"{rec['start']}  {result.estimate.method}  ({len(rec['modes'])} modes)")
            rec["plot"] = str(Path(str(plots_name)) / name)
    progress(len(windows), len(windows))
    return records, n_ok, used, bands
