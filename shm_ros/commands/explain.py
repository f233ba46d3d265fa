"""`shm-ros explain`: what physics the nominal model is missing (docs/interfaces.md §5, docs/explain.md).

    shm-ros explain --structure S.yaml (--modes TABLE.csv | --bag BAG) --out DIR [--window S]

Calibrates the structure file's parameters on the tracked modes (``--bag``: identified and tracked
first, as ``shm-ros update --bag``), analyses what remains (what it co-varies with, where it acts,
modes no model mode can pair with), fits the candidate physics that the residuals point to,
compares them by evidence with the nominal model and keeps those that clear the shipped threshold
and improve the held-out windows. Writes ``DIR/verdict.json``, ``DIR/explain_series.json`` (the
figures' numbers) and ``DIR/report.html``; prints the verdict.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

MAX_TD_EVENTS = 60  # --bag: more event windows than this are a dense campaign, the modal path's alone


def add_parser(sub: argparse._SubParsersAction) -> None:
    from shm_ros.commands.checks import add_overwrite, min_float
    from shm_ros.commands.options import add_options
    from shm_ros.core.explain.config import ExplainConfig
    from shm_ros.core.explain.timedomain import TimeDomainConfig
    from shm_ros.core.ingest.config import MIN_WINDOW_S

    p = sub.add_parser("explain", help="locate the mismatch, name the missing physics, show the fit improve",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--structure", required=True, help="structure file (YAML, docs/interfaces.md §2)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--modes", help="tracked-modes table (CSV, docs/interfaces.md §4)")
    src.add_argument("--bag", help="recording (rosbag2); identified and tracked first")
    src.add_argument("--events", help="recording (rosbag2) of earthquake events with the structure's measured "
                     "input: explained in the time domain (docs/explain.md, Time domain)")
    p.add_argument("--window", type=min_float(MIN_WINDOW_S), default=None,
                   help="--bag/--events: window length, s (default: the ingest default, 600; an event shorter "
                   "than it is one window of its own length)")
    p.add_argument("--out", required=True, help="output directory (new or empty; see --overwrite)")
    add_overwrite(p)
    p.add_argument("--no-report", action="store_true", help="skip report.html")
    add_options(p.add_argument_group("explain (ExplainConfig; the explain node's parameters of the same names)"),
                ExplainConfig)
    add_options(p.add_argument_group("--events: time domain (TimeDomainConfig; the explain node's time_domain.*)"),
                TimeDomainConfig, "time_domain.")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from dataclasses import asdict

    from shm_ros.commands.checks import Outputs, input_file, input_path, output_dir
    from shm_ros.commands.options import config_from_args
    from shm_ros.core.explain.config import ExplainConfig
    from shm_ros.core.explain.types import Verdict
    from shm_ros.errors import InputError, NoWindowsError
    from shm_ros.io.structure import load_structure
    from shm_ros.io.verdict_files import write_verdict

    input_file(args.structure, "--structure")
    input_file(args.modes, "--modes")
    input_path(args.bag, "--bag")
    input_path(args.events, "--events")
    output_dir(args.out, "--out", args.overwrite)
    out = Path(args.out)
    try:
        config = config_from_args(ExplainConfig, args)
    except (TypeError, ValueError) as exc:
        raise InputError(f"explain options: {exc}") from None
    spec = load_structure(args.structure)
    status = 0
    try:
        verdict = _verdict(args, spec, config)
    except NoWindowsError as exc:  # nothing to analyse: a verdict that says so, exit code 3
        verdict, status = Verdict.no_windows(str(exc)), exc.exit_code
    cfg = asdict(config) | {"structure": args.structure, "modes": args.modes, "bag": args.bag, "events": args.events}
    with Outputs(out) as stage:
        write_verdict(stage, verdict, cfg, getattr(config, "seed", None))
        if not args.no_report:
            from shm_ros.report.build import build_report
            from shm_ros.report.inputs import ExplainInputs, ReportInputs

            inputs = ReportInputs(title=f"shm_ros explain: {spec.name}")
            inputs.explain = ExplainInputs.from_files(stage)
            inputs.facts["structure"] = args.structure
            build_report(inputs, stage)
    path = out / "verdict.json"
    print(format_verdict(verdict.to_dict()))
    print(f"wrote {path}")
    return status


def _verdict(args: argparse.Namespace, spec, config):
    """The verdict of the chosen source (``--events``, ``--modes`` or ``--bag``). Errors the user can
    act on are :class:`shm_ros.errors.ShmError` and reach the command line's one-line message; any
    other exception is a bug and shows its traceback."""
    from shm_ros.core.explain.explain import explain
    from shm_ros.core.models import build_model
    from shm_ros.core.progress import Progress

    if args.events:
        return _events_verdict(args, spec, config)
    if args.modes:
        from shm_ros.io.tables import read_tracked_modes

        obs = read_tracked_modes(args.modes)
    else:
        from shm_ros.io.tracked_source import tracked_observations_from_bag

        model = build_model(spec)
        observed = model.observed_sensors(spec.sensor_ids)
        obs = tracked_observations_from_bag(
            args.bag, spec, observed, args.window,
            lambda text: print(f"shm-ros explain: note: {text}", file=sys.stderr))
    bar = Progress("explain", every_s=2.0)  # explain reports (stage, fraction done)
    verdict = explain(obs, spec, config, progress=lambda stage, frac: bar(int(round(100 * frac)), 100))
    if args.bag and spec.input_sensor_ids():
        verdict = _with_time_path(args, spec, config, verdict)
    return verdict


def _with_time_path(args: argparse.Namespace, spec, config, modal):
    """``--bag`` on a recording of sparse events with a measured input: the time-domain path too, where
    it helps (at least ``MIN_EVENTS`` event windows with a usable input record, at most
    ``MAX_TD_EVENTS``: a dense campaign's many windows are the modal path's), and one verdict of both
    (:func:`shm_ros.core.explain.td_paths.merge_paths`: the fit ratio the larger of the two)."""
    from shm_ros.core.explain.td_paths import merge_paths
    from shm_ros.core.explain.timedomain import MIN_EVENTS
    from shm_ros.errors import NoWindowsError, NumericalFailure

    try:
        records = _event_records(args.bag, spec, args.window)
    except NoWindowsError:
        return modal
    if not MIN_EVENTS <= len(records) <= MAX_TD_EVENTS:
        return modal
    print(f"shm-ros explain: note: {len(records)} event windows with a measured input: the time-domain path "
          "runs beside the per-event modal estimates", file=sys.stderr)
    try:
        events = _events_explain(args, spec, config, records)
    except NumericalFailure as exc:  # the time path's nominal calibration failed: the modal verdict stands
        modal.notes.append(f"time-domain path not used: {exc}")
        return modal
    return merge_paths(modal, events)


def _events_verdict(args: argparse.Namespace, spec, config):
    """The time-domain path: the bag's event windows (docs/interfaces.md §1) as records of the
    structure's measured input and outputs, explained by :func:`explain_events`. The options
    ``--time-domain.*`` apply, and of the modal path's ``--threshold``, ``--tie-nats`` and ``--seed``
    (a ``--time-domain.`` option of the same name wins)."""
    from shm_ros.errors import InputError

    if not spec.input_sensor_ids():
        raise InputError(f"{args.structure}: --events needs a measured input (`input: {{sensor: ...}}`), and "
                         "the structure declares none")
    return _events_explain(args, spec, config, _event_records(args.events, spec, args.window))


def _event_records(path: str, spec, window_s: float | None) -> list:
    """The recording's event windows (docs/interfaces.md §1) as records of the structure's measured
    input and outputs; an event without a usable input record is left out, and said so."""
    from shm_ros.core.models import build_model
    from shm_ros.core.predict import event_from_window
    from shm_ros.errors import InputError, NoWindowsError
    from shm_ros.io.recording import windows_from_bag
    from shm_ros.io.tracked_source import event_ingest

    # None: the ingest default (600 s); events by STA/LTA or the strong-motion peak (event_ingest)
    config = event_ingest(spec)
    windows, _ = windows_from_bag(path, spec, window_s, config=config)
    events = [w for w in windows if w.is_event]
    if events and len(windows) <= MAX_TD_EVENTS:
        # sparse records (a burst per event): a weak event below the triggers, recorded as a burst of its
        # own (shorter than the window length), is still a record of the measured input and the response,
        # and the weak end of the amplitude range
        length = window_s or (config.window_s if config is not None else 600.0)
        events = [w for w in windows if w.is_event or w.duration_s < 0.95 * length]
    if not events:
        raise NoWindowsError(f"{path}: no event window among its {len(windows)} window(s)")
    model = build_model(spec)
    records = []
    for w in events:
        try:
            records.append(event_from_window(w, model))
        except InputError as exc:  # an event without a usable input record is left out, and said so
            print(f"shm-ros explain: note: {exc}; event left out", file=sys.stderr)
    if not records:
        raise NoWindowsError(f"{path}: no event window with a usable input record")
    return records


def _events_explain(args: argparse.Namespace, spec, config, records: list):
    """:func:`explain_events` with the ``--time-domain.*`` options (and the modal path's ``--threshold``,
    ``--tie-nats``, ``--seed`` where no ``--time-domain.`` option of the same name is given)."""
    from shm_ros.commands.options import config_from_args
    from shm_ros.core.explain.timedomain import TimeDomainConfig, explain_events

    cfg = config_from_args(TimeDomainConfig, args, "time_domain.",
                           TimeDomainConfig(threshold=config.threshold, tie_nats=config.tie_nats, seed=config.seed))
    return explain_events(records, spec, cfg, progress=lambda text: print(f"shm-ros explain: {text}", file=sys.stderr))


def format_verdict(v: dict) -> str:
    """A few lines for the terminal: mismatch summary, accepted physics, fit before / after."""
    lines = [f"mismatch: {v['mismatch']['summary']}"]
    if v.get("status", "ok") != "ok":
        return "\n".join([*lines, f"status: {v['status']} (nothing was analysed)"])
    from shm_ros.core.explain.fit_ratio import fit_sentence

    lines.append(fit_sentence(v))
    if not v["missing_physics"]:
        lines.append("missing physics: none (the nominal model explains the data)" if v.get("model_fits")
                     else "missing physics: none named")
    for i, m in enumerate(v["missing_physics"], 1):
        where = f" at {m['where']}" if m.get("where") else ""
        when = f" from {m['time']}" if m.get("time") else ""
        down = m.get("downgraded_by")
        flags = "".join([", its form does not fit what it explains" if m.get("form_fits") is False else "",
                         f", downgraded by the {down.replace('_', '-')}" if down else ""])
        lines.append(f"{i}. {m['name']}{where}{when}: {m['form']} (log evidence gain {m['log_evidence_gain']:.1f}"
                     f"{flags})")
    failed = [c["label"] for c in v.get("candidates", []) if c.get("failed")]
    if failed:
        lines.append(f"failed (numerical): {', '.join(failed)}")
    f = v["fit"]
    if "nrms_pct" in f["before"]:  # the time-domain path
        lines.append(f"NRMS {f['before']['nrms_pct']:.1f} % -> {f['after'].get('nrms_pct', float('nan')):.1f} %; "
                     f"held out {f['held_out']['before'].get('nrms_pct', float('nan')):.1f} % -> "
                     f"{f['held_out']['after'].get('nrms_pct', float('nan')):.1f} %")
        return "\n".join(lines)
    lines.append(f"frequency RMSE {f['before'].get('frequency_rmse_pct', float('nan')):.2f} % -> "
                 f"{f['after'].get('frequency_rmse_pct', float('nan')):.2f} %; held out "
                 f"{f['held_out']['before'].get('frequency_rmse_pct', float('nan')):.2f} % -> "
                 f"{f['held_out']['after'].get('frequency_rmse_pct', float('nan')):.2f} %")
    from shm_ros.core.explain.whiteness import listing

    w = f.get("residual_whiteness")
    if w and any(m["name"] != "unmodelled_modes" for m in v["missing_physics"]):
        left = w["still_structured"]
        rho = [w["lag1_after"][w["mode_numbers"].index(m)] for m in left]
        modes, values = listing(left, rho)
        lines.append(f"misfit left: a course in time on {modes} (lag-1 autocorrelation {values})" if left
                     else f"misfit left: noise on every mode (lag-1 autocorrelation at most "
                          f"{max(w['lag1_after'], default=0.0):.2f})")
    return "\n".join(lines)

