"""`shm-ros simulate SCENARIO --out DIR`: a recording whose truth is known.

Writes ``DIR/bag`` (bag of docs/interfaces.md §1: AccelBlock or per-sample Imu, temperature), ``DIR/structure.yaml``
(the NOMINAL structure file), ``DIR/truth.json`` (true modal properties per window, hidden effects,
faults, seed) and ``DIR/truth_modes.csv`` (the true modes as a tracked-modes table). Scenarios: girder, building,
building-earthquake, or a YAML file (--scenario-file).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    from shm_ros.commands.checks import add_overwrite, min_float, positive_float, positive_int

    p = sub.add_parser("simulate", help="simulate a monitoring campaign with known truth",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenario", nargs="?", default=None,
                   help="girder | building | building-earthquake | girder-roving (a robot with a roving sensor, "
                        "docs/roving.md) | building-roving (a drone perching on the floors) (default: girder, "
                        "or the scenario file's)")
    p.add_argument("--out", required=True, help="output directory (bag/, structure.yaml, truth.json, truth_modes.csv; "
                   "new or empty, see --overwrite)")
    add_overwrite(p)
    p.add_argument("--scenario-file",
                   help="YAML scenario: {scenario: NAME, <option>: value, effects: [...], faults: [...]}")
    p.add_argument("--windows", type=positive_int, help="number of windows (bursts)")
    p.add_argument("--duration", type=positive_float,
                   help="total recorded seconds: one window of that length if shorter than --window-s, "
                        "else that many seconds' worth of windows")
    p.add_argument("--window-s", type=min_float(1.0),
                   help="length of each burst, s (girder/building 600, earthquake 300)")
    p.add_argument("--pause-s", type=min_float(1.0), help="pause between bursts, s (default 2; must exceed 1)")
    p.add_argument("--fs", type=positive_float, help="sample rate, Hz (default 100)")
    p.add_argument("--floors", type=positive_int, help="building scenarios: number of stories (default 8)")
    p.add_argument("--start",
                   help="start time, ISO 8601 UTC (girder 2024-03-01T00:00:00Z, building 2024-05-01T00:00:00Z)")
    p.add_argument("--effects", default="",
                   help="hidden effects, comma-separated key[@TIME][:name=value...]: temperature_linear, "
                        "temperature_bilinear, damage, repair, added_mass, support_flexibility, "
                        "amplitude_stiffness, amplitude_damping, damper "
                        "(e.g. 'temperature_bilinear:where=bearings,damage@48h:factor=0.9')")
    p.add_argument("--faults", default="",
                   help="sensor faults, comma-separated kind[@WINDOW][:SENSOR]: dropout, spike, nan, dead, "
                        "clipped, clock_jump, duplicate")
    p.add_argument("--format", choices=("imu", "block"),
                   help="per-sample sensor_msgs/Imu or AccelBlock (default block)")
    p.add_argument("--storage", choices=("mcap", "sqlite3"), help="bag storage (default mcap)")
    p.add_argument("--no-compress", action="store_true", help="do not zstd-compress MCAP chunks")
    p.add_argument("--unrelated-topics", action="store_true",
                   help="also record a std_msgs/String status topic that the pipeline must ignore")
    p.add_argument("--seed", type=int, help="random seed (default 0); the same seed gives byte-identical bags")
    p.add_argument("--workers", type=positive_int, default=1, help="processes computing windows (default 1)")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=run)


def build_scenario(args: argparse.Namespace):
    from shm_ros.core.simulate import EffectRequest, named_scenario, parse_effects, parse_faults, scenario_from_dict

    if args.scenario_file:
        from shm_ros.io.structure import read_yaml

        try:
            text = Path(args.scenario_file).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise ValueError(f"{args.scenario_file}: cannot read scenario file: {exc}") from None
        data = read_yaml(text, args.scenario_file) or {}
        if not isinstance(data, dict):
            raise ValueError(f"{args.scenario_file}: a scenario file must be a YAML mapping")
        if args.scenario:
            data["scenario"] = args.scenario
        if args.floors is not None:
            data["n_floors"] = args.floors
        sc = scenario_from_dict(data, source=args.scenario_file)
    else:
        sc = named_scenario(args.scenario or "girder", n_floors=args.floors)
    for opt, field in (("window_s", "window_s"), ("pause_s", "pause_s"), ("fs", "fs"), ("start", "start"),
                       ("seed", "seed"), ("format", "output"), ("storage", "storage")):
        v = getattr(args, opt)
        if v is not None:
            setattr(sc, field, v)
    if args.no_compress:
        sc.compress = False
    if args.unrelated_topics:
        sc.unrelated_topics = True
    if args.windows is not None:
        sc.n_windows = args.windows
    if args.duration is not None:
        if args.duration <= 0:
            raise ValueError("--duration must be > 0")
        if args.duration <= sc.window_s:
            sc.window_s, sc.n_windows = args.duration, 1
        else:
            sc.n_windows = max(1, math.ceil(args.duration / sc.window_s - 1e-9))
    if args.effects:
        sc.effects = sc.effects + [EffectRequest(k, p) for k, p in parse_effects(args.effects)]
    if args.faults:
        sc.faults = sc.faults + parse_faults(args.faults)
    return sc


def run(args: argparse.Namespace) -> int:
    from shm_ros.commands.checks import input_file, output_dir
    from shm_ros.core.simulate import simulate_campaign
    from shm_ros.errors import InputError
    from shm_ros.io.campaign import print_progress, write_campaign

    input_file(args.scenario_file, "--scenario-file")
    output_dir(args.out, "--out", args.overwrite)
    if args.scenario in ("girder-roving", "building-roving"):
        from shm_ros.commands.roving import simulate as simulate_roving

        return simulate_roving(args)
    try:
        sc = build_scenario(args)
        campaign = simulate_campaign(sc)
    except ValueError as exc:  # the scenario's own checks name the option or field
        raise InputError(str(exc)) from None
    every = max(1, campaign.n_windows // 50)
    files = write_campaign(campaign, args.out, workers=args.workers,
                           progress=None if args.quiet else print_progress(every),
                           command_config={"effects": args.effects, "faults": args.faults}, overwrite=args.overwrite)
    print(f"wrote {files.n_windows} windows: {files.bag} ({files.bag_bytes / 1e6:.1f} MB), "
          f"{files.structure}, {files.truth} in {files.seconds:.1f} s")
    return 0
