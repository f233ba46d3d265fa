"""`shm-ros predict`: drive the (updated) model with each event's measured input (docs/interfaces.md §7).

    shm-ros predict --structure S.yaml [--posterior DIR|posterior.json] (--bag BAG | --windows W.npz ...)
                    [--calibration-windows C.npz ...] --out DIR [--all-windows] [--n-draws N] [--seed S]
                    [--no-plots]

Without ``--posterior`` the nominal model alone is predicted. Events are the windows that ingest
flags (``is_event``, docs/interfaces.md §1); ``--all-windows`` predicts every window. Writes
``DIR/prediction.json`` (per event and channel: NRMS of the updated and the nominal model, band
coverage, peaks and intervals at unmeasured floors and drifts; the Table-3 rows; a summary),
prints the Table-3 NRMS table, and draws ``DIR/prediction_<window>.png`` per event.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any


def add_parser(sub: argparse._SubParsersAction) -> None:
    from shm_ros.commands.checks import add_overwrite, min_float
    from shm_ros.commands.options import add_options
    from shm_ros.core.ingest.config import MIN_WINDOW_S
    from shm_ros.core.predict import PredictConfig

    p = sub.add_parser("predict", help="predict events' responses with the (updated) model",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--structure", required=True, help="structure file (YAML, docs/interfaces.md §2)")
    p.add_argument("--posterior", default=None, help="posterior.json or the folder of `shm-ros update`")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--bag", help="recording (rosbag2); windowed as `shm-ros ingest` does")
    src.add_argument("--windows", nargs="+", help="window files (.npz, as `shm-ros ingest --windows` writes)")
    p.add_argument("--window", type=min_float(MIN_WINDOW_S), default=600.0,
                   help="--bag: window length, s (default 600)")
    p.add_argument("--all-windows", action="store_true", help="predict every window, not only events")
    p.add_argument("--calibration-windows", nargs="+", default=None,
                   help="window files (.npz) of the events the posterior was calibrated on (two or more): the "
                        "model error is learnt from them out of sample (leave one event out)")
    p.add_argument("--out", required=True, help="output directory (new or empty; see --overwrite)")
    add_overwrite(p)
    p.add_argument("--no-plots", action="store_true", help="skip the figures")
    add_options(p.add_argument_group("prediction (PredictConfig; the predict node's parameters of the same "
                                     "names)"), PredictConfig)
    p.set_defaults(func=run)


def load_windows(args: argparse.Namespace, spec: Any) -> list:
    if args.bag:
        from shm_ros.io.recording import windows_from_bag

        windows, _ = windows_from_bag(args.bag, spec, args.window)
        return list(windows)
    from shm_ros.io.window_files import load_window

    return [load_window(p) for p in args.windows]


def learn_model_error(model: Any, posterior: Any, calibration: list, config: Any) -> Any:
    """The model error learnt out of sample from ``calibration`` (the windows ``posterior`` was
    calibrated on, two or more) by leave-one-event-out cross-validation from the posterior's MAP."""
    import numpy as np

    from shm_ros.core.predict import draws_from_posterior, event_from_window
    from shm_ros.core.predict.model_error import cross_validated_error

    if posterior is None:
        raise ValueError("calibration windows need the posterior they calibrated (--posterior)")
    theta_map = draws_from_posterior(posterior, model, 0, np.random.default_rng(0), config.relative_error).theta_map
    return cross_validated_error(model, [event_from_window(w, model) for w in calibration], theta_map, config)


def predict_windows(model: Any, windows: list, posterior: Any, config: Any, calibration: list | None = None,
                    limits: Any = None, model_error: Any = None) -> tuple[list, list[str]]:
    """Predictions of ``windows`` (the same numbers as the predict node's for the same seed).
    ``calibration``: the windows the posterior was calibrated on (two or more: the model error is
    learnt from them by leave-one-event-out cross-validation; ``model_error``: that error already
    learnt, :func:`learn_model_error`); ``limits``: the structure's drift limits (each event's drift
    risk, for models with drift ratios; the out-of-calibration warnings whenever a model error was
    learnt)."""
    import numpy as np

    from shm_ros.core.predict import draws_from_posterior, event_from_window, predict_event
    from shm_ros.core.predict.risk import event_risk

    draws = None if posterior is None else draws_from_posterior(
        posterior, model, config.n_draws, np.random.default_rng(config.seed), config.relative_error)
    if calibration and model_error is None:
        model_error = learn_model_error(model, posterior, calibration, config)
    if model_error is not None:
        if draws is None:
            raise ValueError("a learnt model error needs the posterior it was learnt for")
        draws = draws.with_model_error(model_error)
    preds, errors = [], []
    for w in windows:
        try:
            p = predict_event(model, event_from_window(w, model), draws, config)
        except (ValueError, np.linalg.LinAlgError) as exc:
            errors.append(f"window {w.window_id}: {exc}")
            continue
        if model_error is not None or any(c.quantity == "drift_ratio" for c in p.channels):
            # drift exceedance where the model has drift ratios; the PGA check wherever calibration
            # events were given (a model without story heights still has an input PGA)
            p.risk = event_risk(p, limits)
            p.notes.extend(p.risk["warnings"])
        preds.append(p)
    return preds, errors


def run(args: argparse.Namespace) -> int:
    from dataclasses import asdict

    from shm_ros.commands.checks import Outputs, input_file, input_path, output_dir
    from shm_ros.commands.options import config_from_args
    from shm_ros.core.models import build_model
    from shm_ros.core.predict import PredictConfig, event_json, format_table3, summary_json, table3_row
    from shm_ros.core.provenance import stamp_output
    from shm_ros.errors import InputError, NoWindowsError
    from shm_ros.io import jsonio
    from shm_ros.io.structure import load_structure

    input_file(args.structure, "--structure")
    input_path(args.posterior, "--posterior")
    input_path(args.bag, "--bag")
    for w in args.windows or []:
        input_file(w, "--windows")
    output_dir(args.out, "--out", args.overwrite)
    out = Path(args.out)
    try:
        config = config_from_args(PredictConfig, args).validate()
    except (TypeError, ValueError) as exc:
        raise InputError(f"prediction options: {exc}") from None
    spec = load_structure(args.structure)
    model = build_model(spec)
    posterior = None
    if args.posterior:
        from shm_ros.report.load import load_posterior

        posterior = load_posterior(args.posterior)
    windows = load_windows(args, spec)
    if not windows:
        raise NoWindowsError(f"{args.bag}: no window found (shm-ros ingest lists the diagnostics)")
    from shm_ros.io.window_files import load_window

    for p in args.calibration_windows or []:
        input_file(p, "--calibration-windows")
    calibration = [load_window(p) for p in args.calibration_windows or []]
    if len(calibration) == 1:
        raise InputError("--calibration-windows: give two or more events (one is left out at a time)")
    chosen = windows if args.all_windows else [w for w in windows if w.is_event]
    if not chosen:
        raise NoWindowsError(f"no event among {len(windows)} windows (--all-windows predicts every one)")
    try:
        preds, errors = predict_windows(model, chosen, posterior, config, calibration, spec.drift_limits)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    for e in errors:
        print(f"shm-ros predict: {e}", file=sys.stderr)
    rows = [table3_row(model, p) for p in preds]
    payload = {"model": "updated" if posterior is not None else "nominal",
               "events": [event_json(p) for p in preds], "table3": rows, "summary": summary_json(preds),
               "errors": errors}
    cfg = asdict(config) | {"structure": args.structure, "posterior": args.posterior, "bag": args.bag}
    from shm_ros.io.prediction_files import write_prediction_series

    with Outputs(out) as stage:
        jsonio.dump(stamp_output(payload, cfg, config.seed), stage / "prediction.json", indent=2)
        write_prediction_series(stage, preds)  # the report's predicted-vs-measured figures
        if not args.no_plots:
            from shm_ros.report.prediction import plot_event

            for p in preds:
                plot_event(p, stage / f"prediction_{p.window_id}.png")
    doc = out / "prediction.json"
    print(format_table3(rows))
    print(f"{len(preds)} events predicted -> {doc}")
    return 0 if preds else 1
