"""`shm-ros batch ARCHIVE... --out DIR`: re-process an archive of bags.

    shm-ros batch ARCHIVE... --out DIR [--structure S.yaml] [--engine dask|serial]
                  [--scheduler tcp://host:8786] [--workers 2] [--config batch.yaml]

Every bag found under ARCHIVE (folders are searched; a bag is a rosbag2 folder or an .mcap file)
goes through ingest -> identify; then, per structure, the windows of all its bags are tracked and,
where the structure file has parameters, the model is updated. A bag's structure is --structure, or
the nearest structure.yaml in its folder or above it, so one archive may hold many structures.
The jobs run on Dask: a local cluster of --workers single-threaded processes by default, or the
cluster whose scheduler is --scheduler. --config is YAML with optional sections `identify`,
`track`, `update` (each a mapping of that stage's options) and `window_s`.
A killed batch resumes: the same command again skips the bags it had finished (kept in
DIR/.bags/ until the outputs are written).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any


def add_parser(sub: argparse._SubParsersAction) -> None:
    from shm_ros.commands.checks import add_overwrite, min_float, positive_int

    p = sub.add_parser("batch", help="re-process an archive of bags (Dask)", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("archive", nargs="+", help="bags, or folders holding bags")
    p.add_argument("--out", required=True, help="output folder (new or empty; see --overwrite)")
    add_overwrite(p)
    p.add_argument("--structure", help="structure file of every bag (default: structure.yaml next to each bag)")
    p.add_argument("--engine", choices=("dask", "serial"), default="dask",
                   help="dask (default: a local cluster, or --scheduler) or serial (this process)")
    p.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. tcp://host:8786")
    p.add_argument("--workers", type=positive_int, default=2, help="local cluster: worker processes (default 2)")
    p.add_argument("--window", type=min_float(1.0), default=None, help="window length in s (default 600)")
    p.add_argument("--config", help="YAML with sections identify, track, update")
    p.add_argument("--no-update", action="store_true", help="stop after tracking")
    p.set_defaults(func=run)


def settings_from(args: argparse.Namespace):
    from shm_ros.batch.jobs import BatchSettings

    doc: dict[str, Any] = {}
    if args.config:
        from shm_ros.io.structure import read_yaml

        doc = read_yaml(Path(args.config).read_text(encoding="utf-8"), args.config) or {}
        if not isinstance(doc, dict):
            raise ValueError(f"{args.config}: must be a mapping with sections identify/track/update")
        unknown = set(doc) - {"identify", "track", "update", "window_s"}
        if unknown:
            raise ValueError(f"{args.config}: unknown section(s) {sorted(unknown)}")
    s = BatchSettings(window_s=float(args.window or doc.get("window_s", 600.0)),
                      identify=dict(doc.get("identify") or {}), track=dict(doc.get("track") or {}),
                      update=dict(doc.get("update") or {}), run_update=not args.no_update)
    # fail here, naming the file, rather than in every job
    from shm_ros.core.bayes.update import UpdateConfig
    from shm_ros.core.identify import IdentifyConfig
    from shm_ros.core.tracking import TrackingConfig

    try:
        IdentifyConfig.from_dict(s.identify).validate()
        TrackingConfig(**s.track)
        UpdateConfig(**s.update).validate()
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{args.config}: {exc}") from exc
    return s


def run(args: argparse.Namespace) -> int:
    from shm_ros.batch.archive import archive
    from shm_ros.batch.engines import make_engine
    from shm_ros.batch.run import run_batch
    from shm_ros.commands.checks import input_file, input_path, output_dir
    from shm_ros.errors import InputError

    for a in args.archive:
        input_path(a, "ARCHIVE")
    input_file(args.structure, "--structure")
    input_file(args.config, "--config")
    output_dir(args.out, "--out", args.overwrite)
    try:
        settings = settings_from(args)
        bags = archive(args.archive, args.structure)
    except (OSError, ValueError) as exc:
        raise InputError(str(exc)) from None
    engine = make_engine(args.engine, args.scheduler, args.workers)
    try:
        summary = run_batch(bags, settings, engine, args.out, log=lambda s: print(f"[batch] {s}", flush=True))
    finally:
        engine.close()
    errors = [e for b in summary["bags"] for e in b["errors"]] + \
             [e for s in summary["structures"] for e in s["errors"]]
    for e in errors:
        print(f"shm-ros batch: {e}", file=sys.stderr)
    return 0 if all(s["tracked"] for s in summary["structures"]) else 1
