"""`shm-ros ingest BAG --structure S.yaml --out DIR [--window SECONDS]`: a bag -> checked windows.

Writes ``DIR/windows.json`` (one record per window: start, end, rate, channels, channel status,
temperature, event flag, PGA, flagged-sample counts, notes; plus every diagnostic, the dropped
stretches and counters; ``schema_version`` and ``provenance``) and ``DIR/windows/wNNNNN_<start>.npz``
(the raw samples and flags of each window; ``shm_ros.io.window_files.load_window`` reads one back).
Every ingest setting is a flag (``--snap-tolerance``, ``--event-detector``, ...).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    from shm_ros.commands.checks import add_overwrite
    from shm_ros.commands.options import add_options
    from shm_ros.core.ingest import IngestConfig

    p = sub.add_parser("ingest", help="check, align and window a recording (bag -> windows)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bag", help="rosbag2 bag (MCAP or sqlite3 directory)")
    p.add_argument("--structure", required=True, help="structure YAML (its sensors name the channels)")
    p.add_argument("--out", required=True, help="output directory (new or empty; see --overwrite)")
    add_overwrite(p)
    p.add_argument("--no-samples", action="store_true", help="write only windows.json, no .npz")
    p.add_argument("--quiet", action="store_true", help="print only errors and the summary line")
    # every windowing option (the streaming-only ones are node parameters)
    add_options(p.add_argument_group("ingest options"), IngestConfig, aliases={"window_s": ["--window"]})
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from shm_ros.commands.checks import Outputs, input_file, input_path, output_dir
    from shm_ros.commands.options import config_from_args
    from shm_ros.core.ingest import IngestConfig, windows_summary
    from shm_ros.core.provenance import stamp_output
    from shm_ros.errors import InputError, NoWindowsError
    from shm_ros.io import jsonio
    from shm_ros.io.recording import ingest_bag
    from shm_ros.io.structure import load_structure
    from shm_ros.io.window_files import save_window, window_filename

    input_path(args.bag, "BAG")
    input_file(args.structure, "--structure")
    output_dir(args.out, "--out", args.overwrite)
    spec = load_structure(args.structure)
    try:
        config = config_from_args(IngestConfig, args)
    except ValueError as exc:
        raise InputError(f"ingest options: {exc}") from None
    res = ingest_bag(args.bag, spec, window_s=config.window_s, config=config)
    for d in res.mismatches:  # a misspelt topic or sensor id: say so before anything else
        print(f"shm-ros ingest: {args.bag}: warning: {d.message}", file=sys.stderr)
    out = Path(args.out)
    records = windows_summary(res.windows)
    with Outputs(out) as stage:
        if not args.no_samples:
            wdir = stage / "windows"
            wdir.mkdir()
            for i, (w, rec) in enumerate(zip(res.windows, records, strict=True)):
                name = window_filename(i, w)
                save_window(wdir / name, w)
                rec["file"] = f"windows/{name}"
        payload = {
            "bag": str(args.bag),
            "structure": str(args.structure),
            "sample_rate_hz": res.sample_rate_hz,
            "sample_rates_hz": list(res.sample_rates_hz),
            "windows": records,
            "dropped": [{"start_ns": d.start_ns, "end_ns": d.end_ns, "n_samples": d.n_samples, "reason": d.reason}
                        for d in res.dropped],
            "diagnostics": [d.to_dict() for d in res.diagnostics],
            "diagnostic_counts": {f"{code} {src}": n for (code, src), n in sorted(res.diagnostic_counts.items())},
            "ignored_topics": res.ignored_topics,
            "stats": {"samples_in": res.stats.samples_in, "samples_windowed": res.stats.samples_windowed,
                      "samples_not_windowed": dict(res.stats.samples_not_windowed),
                      "messages_rejected": res.stats.messages_rejected, "messages": res.messages,
                      "implausible": res.stats.implausible},
        }
        cfg = {"ingest": dataclasses.asdict(config), "structure": str(args.structure), "bag": str(args.bag)}
        jsonio.dump(stamp_output(payload, cfg), stage / "windows.json")
    for d in res.diagnostics:  # --quiet keeps the errors: they say why windows are missing
        if d.level >= 2 or (d.level >= 1 and not args.quiet):
            print(str(d), file=sys.stderr)
    n_err = sum(1 for d in res.diagnostics if d.level >= 2)
    n_warn = sum(1 for d in res.diagnostics if d.level == 1)
    print(f"{len(res.windows)} windows, {res.stats.samples_windowed} of {res.stats.samples_in} channel samples "
          f"windowed, {n_warn} warnings, {n_err} errors -> {out / 'windows.json'}")
    if not res.windows:
        raise NoWindowsError(f"{args.bag}: no window found (see the diagnostics above and in "
                             f"{out / 'windows.json'})")
    return 0
