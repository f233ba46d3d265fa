"""`shm-ros report --out DIR [--windows DIR] [--modes modes.json] [--tracking DIR|CSV]
[--posterior DIR|posterior.json [--samples samples.npz]] [--prediction DIR] [--verdict DIR]
[--truth truth.json]`.

Builds one report from the files the other commands wrote, with a section for each stage given:
data health (``shm-ros ingest``'s folder), identification (``shm-ros identify``'s modes JSON;
stabilization diagrams too when ``--windows`` holds the windows' samples), tracking (``shm-ros
track``'s folder or its ``tracked_modes.csv``), posterior (``shm-ros update``'s folder or its
``posterior.json`` with ``samples.npz``), prediction (``shm-ros predict``'s folder),
explanation (``shm-ros explain``'s folder), against the
simulator's ``truth.json``.

Writes ``DIR/report.html`` (self-contained: opens offline, figures embedded), ``DIR/report.md``
and ``DIR/figures/`` (each PNG with a CSV or JSON of its numbers next to it).
"""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    from shm_ros.commands.checks import add_overwrite, nonneg_int

    p = sub.add_parser("report", help="one HTML/Markdown report over the stages' outputs",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="output directory (new or empty; see --overwrite)")
    add_overwrite(p)
    p.add_argument("--windows", help="output folder of `shm-ros ingest` (or its windows.json)")
    p.add_argument("--modes", help="modes JSON of `shm-ros identify`")
    p.add_argument("--tracking", help="output folder of `shm-ros track` (or its tracked_modes.csv)")
    p.add_argument("--posterior", help="output folder of `shm-ros update` (or its posterior.json)")
    p.add_argument("--samples", help="samples.npz of `shm-ros update` (default: next to posterior.json)")
    p.add_argument("--prediction", help="output folder of `shm-ros predict` (or its prediction.json)")
    p.add_argument("--verdict", help="output folder of `shm-ros explain` (or its verdict.json)")
    p.add_argument("--truth", help="truth.json of `shm-ros simulate`")
    p.add_argument("--diagrams", type=nonneg_int, default=3,
                   help="stabilization diagrams recomputed from --windows samples (default 3; 0 = none)")
    p.add_argument("--title", default="shm_ros report", help="report title")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from shm_ros.commands.checks import Outputs, input_path, output_dir
    from shm_ros.report.build import build_report
    from shm_ros.report.inputs import ReportInputs
    from shm_ros.report.load import (
        ReportInputError,
        load_identify,
        load_ingest,
        load_json,
        load_posterior,
        load_tracking,
    )

    for opt in ("windows", "modes", "tracking", "posterior", "samples", "prediction", "verdict", "truth"):
        input_path(getattr(args, opt), f"--{opt}")
    output_dir(args.out, "--out", args.overwrite)
    inputs = ReportInputs(title=args.title)
    if args.windows:
        inputs.ingest = load_ingest(args.windows)
        inputs.facts["windows"] = args.windows
    if args.modes:
        wdir = None
        if args.windows:
            w = Path(args.windows)
            wdir = w.parent if w.is_file() else w
        inputs.identify = load_identify(args.modes, wdir, args.diagrams)
        from shm_ros.report.load import load_json

        doc = load_json(args.modes)
        if doc.get("global_modes") is not None:  # a roving campaign (docs/interfaces.md section 8)
            inputs.roving = doc
        inputs.facts["modes"] = args.modes
    if args.tracking:
        inputs.tracking = load_tracking(args.tracking)
        inputs.facts["tracking"] = args.tracking
    if args.posterior:
        inputs.posterior = load_posterior(args.posterior, args.samples)
        inputs.facts["posterior"] = args.posterior
    from shm_ros.report.inputs import ExplainInputs, PredictionInputs

    for path, cls, field, fact in ((args.prediction, PredictionInputs, "prediction", "prediction"),
                                   (args.verdict, ExplainInputs, "explain", "verdict")):
        if path:
            try:
                setattr(inputs, field, cls.from_files(path))
            except (OSError, ValueError) as exc:
                raise ReportInputError(f"{path}: {exc}") from None
            inputs.facts[fact] = path
    if args.truth:
        inputs.truth = load_json(args.truth)
        inputs.facts["truth"] = args.truth
    out = Path(args.out)
    with Outputs(out) as stage:
        files = build_report(inputs, stage)
    print(f"{len(files.sections)} sections ({', '.join(files.sections) or 'none'}), {len(files.figures)} figures "
          f"-> {out / files.html.name}, {out / files.markdown.name}")
    return 0
