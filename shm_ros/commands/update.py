"""`shm-ros update`: Bayesian calibration of a structure file's parameters (docs/interfaces.md §6).

    shm-ros update --structure S.yaml (--modes TABLE.csv | --bag BAG) --out DIR
                   [--sampler mh|emcee] [--likelihood model-error|gaussian|fitness|time] [--study]

Writes ``DIR/posterior.json`` (MAP, mean, std and 95 % interval per parameter, sampler diagnostics,
fit, log evidence, with ``schema_version`` and ``provenance``), ``DIR/samples.npz`` (draws, chains,
log posterior) and ``DIR/corner.png`` / ``DIR/trace.png``. ``--study`` runs the bridge paper's
prior x fitness-weight sweep instead and writes ``DIR/study.json`` and ``DIR/study.txt``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

# older spellings of generated options, still accepted
ALIASES = {"n_chains": ["--chains"], "n_steps": ["--steps"], "rhat_target": ["--rhat"],
           "ess_target": ["--ess"], "use_shapes": ["--shapes"]}


def add_parser(sub: argparse._SubParsersAction) -> None:
    from shm_ros.commands.checks import add_overwrite, min_float
    from shm_ros.commands.options import add_options
    from shm_ros.core.bayes.update import UpdateConfig
    from shm_ros.core.ingest.config import MIN_WINDOW_S

    p = sub.add_parser("update", help="Bayesian updating of the structure's parameters",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--structure", required=True, help="structure file (YAML, docs/interfaces.md §2)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--modes", help="tracked-modes table (CSV, docs/interfaces.md §4)")
    src.add_argument("--bag", help="recording (rosbag2); identified and tracked first")
    p.add_argument("--out", required=True, help="output directory (new or empty; see --overwrite)")
    add_overwrite(p)
    p.add_argument("--study", action="store_true",
                   help="run the prior x (alpha, beta) sweep and print the RMSE/MAC table")
    p.add_argument("--refer-to", metavar="COVARIATE[=VALUE]", default=None,
                   help="remove a linear dependence of the frequencies on a covariate column "
                        "(e.g. temperature_c=10) before updating")
    p.add_argument("--window", type=min_float(MIN_WINDOW_S), default=None, help="--bag: window length, s")
    p.add_argument("--no-plots", action="store_true", help="skip corner and trace plots")
    # defaults are declared once, in the core's config
    add_options(p.add_argument_group("updating (UpdateConfig; the update node's parameters of the "
                                     "same names)"), UpdateConfig, aliases=ALIASES)
    p.set_defaults(func=run)


def _config(args: argparse.Namespace):
    from shm_ros.commands.options import config_from_args
    from shm_ros.core.bayes.update import UpdateConfig

    return config_from_args(UpdateConfig, args)


def _observations(args: argparse.Namespace, spec: Any, model: Any):
    if args.modes:
        from shm_ros.io.tables import read_tracked_modes

        obs = read_tracked_modes(args.modes)
        if args.likelihood == "time":
            raise ValueError("--likelihood time compares accelerations: give --bag, not --modes")
        return obs
    return _from_bag(args, spec, model)


def _from_bag(args: argparse.Namespace, spec: Any, model: Any):
    """Observations from a bag: windows (ingest) -> modes per window (identify) -> mode identities
    across the windows (the tracker of ``shm-ros track``) -> one column per tracked mode; the
    updating pairs the tracked modes with the model's modes once. For ``--likelihood time``, the
    window with the strongest input as an input/output acceleration record."""
    from shm_ros.io.recording import windows_from_bag

    observed = model.observed_sensors(spec.sensor_ids)
    if args.likelihood == "time":
        windows, _ = windows_from_bag(args.bag, spec, args.window or 600.0)
        if not windows:
            from shm_ros.errors import NoWindowsError

            raise NoWindowsError(f"{args.bag}: no usable window in the recording")
        return _acceleration_record(args, [i.sensor for i in model.inputs], windows, observed)
    from shm_ros.io.tracked_source import tracked_observations_from_bag

    return tracked_observations_from_bag(args.bag, spec, observed, args.window,
                                         lambda text: print(f"shm-ros update: note: {text}", file=sys.stderr))


def _acceleration_record(args, inputs, windows, observed):
    from scipy.signal import detrend

    from shm_ros.core.bayes.timedomain import AccelerationRecord

    if not inputs:
        raise ValueError(f"{args.structure}: --likelihood time needs the structure's 'input' sensor")
    inp = inputs[0]
    observed = [s for s in observed if s not in inputs]  # a floor input's sensor is a support, not an output
    usable = [w for w in windows if all(i in w.channel_names for i in inputs)]
    if not usable:
        raise ValueError(f"{args.bag}: no window carries the input sensor(s) {inputs}")

    def strength(w):
        x = w.samples[:, w.channel_names.index(inp)]
        return float(np.nanmax(np.abs(x - np.nanmean(x))))

    w = max(usable, key=strength)
    outs = [s for s in observed if s in w.channel_names]
    cols = [w.channel_names.index(s) for s in [*inputs, *outs]]
    data = w.samples[:, cols]
    good = np.all(np.isfinite(data), axis=1)
    if not good.all():  # keep the longest clean stretch: nothing is interpolated
        edges = np.flatnonzero(np.diff(np.concatenate([[0], good.astype(int), [0]])))
        runs = edges.reshape(-1, 2)
        a, b = runs[np.argmax(runs[:, 1] - runs[:, 0])]
        data = data[a:b]
    data = detrend(data, axis=0, type="linear")  # gravity offset and drift
    n_in = len(inputs)
    return AccelerationRecord(1.0 / w.sample_rate_hz, data[:, :n_in].T, data[:, n_in:], outs,
                              notes=[f"window {w.window_id} (strongest input) used"])


def run(args: argparse.Namespace) -> int:
    from shm_ros.commands.checks import Outputs, input_file, input_path, output_dir
    from shm_ros.core.models import build_model
    from shm_ros.errors import InputError
    from shm_ros.io.posterior_files import write_posterior
    from shm_ros.io.structure import load_structure

    input_file(args.structure, "--structure")
    input_file(args.modes, "--modes")
    input_path(args.bag, "--bag")
    output_dir(args.out, "--out", args.overwrite)
    refer = None
    if args.refer_to:
        name, _, value = args.refer_to.partition("=")
        try:
            refer = (name, float(value) if value else None)
        except ValueError:
            raise InputError(f"--refer-to {args.refer_to!r}: expected COVARIATE or COVARIATE=NUMBER") from None
    try:
        config = _config(args)
        config.validate()
    except (TypeError, ValueError) as exc:
        raise InputError(f"update options: {exc}") from None
    spec = load_structure(args.structure)
    if not spec.parameters:
        raise InputError(f"{args.structure}: field 'parameters': nothing to update")
    model = build_model(spec)
    try:  # a table or recording that does not fit the structure names what does not fit
        obs = _observations(args, spec, model)
        if refer is not None:
            obs = obs.referred_to(*refer)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    for note in getattr(obs, "notes", []):
        print(f"shm-ros update: note: {note}", file=sys.stderr)
    out = Path(args.out)
    with Outputs(out) as stage:
        if args.study:
            return _run_study(args, spec, model, obs, config, stage)
        from shm_ros.core.bayes.update import update
        from shm_ros.core.progress import Progress

        try:
            post = update(model, obs, config, priors=spec.parameters,
                          progress=Progress(f"{config.sampler} steps", every_s=2.0))
        except ValueError as exc:
            raise InputError(str(exc)) from None
        cfg_dict = {k: v for k, v in vars(config).items()}
        cfg_dict.update({"structure": args.structure, "modes": args.modes, "bag": args.bag})
        write_posterior(stage, post, cfg_dict, args.seed)
        if not args.no_plots:
            from shm_ros.report.posterior import posterior_plots

            posterior_plots(post.chains, post.log_prob.reshape(post.chains.shape[:2]), post.chain_names, stage)
    for w in post.warnings:
        print(f"shm-ros update: warning: {w}", file=sys.stderr)
    d = post.diagnostics
    print(f"{'parameter':<16}{'MAP':>10}{'mean':>10}{'std':>10}   95 % interval")
    for n, s in post.parameters.items():
        print(f"{n:<16}{s.map:>10.4f}{s.mean:>10.4f}{s.std:>10.4f}   [{s.ci95[0]:.4f}, {s.ci95[1]:.4f}]")
    print(f"sampler {d['sampler']}: R-hat max {d['rhat_max']:.4f}, ESS min {d['ess_min']:.0f}, "
          f"acceptance {d['acceptance']:.2f}" + ("" if post.log_evidence is None else
                                                 f", log evidence {post.log_evidence:.2f}"))
    print(f"wrote {out / 'posterior.json'}")
    return 0


def _run_study(args, spec, model, obs, config, out: Path) -> int:
    from shm_ros.commands.options import given
    from shm_ros.core.bayes.study import bridge_study, format_table
    from shm_ros.core.priors import priors_from_specs
    from shm_ros.core.provenance import stamp_output
    from shm_ros.io import jsonio

    # the study reproduces the paper's Table 1: J averaged over windows unless --fitness-j is given
    j = config.fitness_j if "fitness_j" in given(args) else "averaged"
    rows = bridge_study(model, obs, priors_from_specs(spec.parameters), config, fitness_j=j)
    table = format_table(rows, rows[0].modes or obs.mode_numbers)
    payload = stamp_output({"fitness_j": j, "definitions": {
        "rmse": "per mode: root mean square over windows of (f_obs - f_model) / f_obs at the "
                "posterior mean",
        "mac": "per mode: mean over windows of MAC(observed shape, model shape at the sensors)"},
        "modes": list(obs.mode_numbers), "rows": [r.to_dict() for r in rows]},
        {k: v for k, v in vars(config).items()}, args.seed)
    jsonio.dump(payload, out / "study.json", indent=2)
    (out / "study.txt").write_text(table + "\n")
    print(table)
    return 0
