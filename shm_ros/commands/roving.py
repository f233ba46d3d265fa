"""The roving-sensor paths of two commands (docs/interfaces.md section 8, docs/roving.md):

* ``shm-ros simulate girder-roving --out DIR``: DIR/bag (Imu per sample, ``/tf``), DIR/structure.yaml,
  DIR/truth.json (the modes without the robot at every point and reference, the clock offset, the
  drive and dwell phases); ``building-roving``: the same for a drone perching on a building's floors;
* ``shm-ros identify BAG --structure S.yaml --out modes.json`` with roving sensors in the structure
  file: setups cut from tf, merged into ``setups`` and ``global_modes``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def simulate(args: argparse.Namespace) -> int:
    import shutil

    from shm_ros.core.simulate.roving import RovingOptions, simulate_roving
    from shm_ros.core.simulate.roving_building import DroneOptions, simulate_building_roving
    from shm_ros.io.jsonio import dump
    from shm_ros.io.roving_bag import write_roving_bag
    from shm_ros.io.structure import dump_structure, load_structure

    out = Path(args.out)
    drone = args.scenario == "building-roving"
    example = Path(__file__).resolve().parents[2] / "examples" / (
        "building_roving.yaml" if drone else "girder_roving.yaml")
    try:
        spec = load_structure(getattr(args, "roving_structure", None) or example)
        opts: RovingOptions | DroneOptions = DroneOptions(seed=args.seed or 0, fs=args.fs or 50.0) if drone \
            else RovingOptions(seed=args.seed or 0, fs=args.fs or 100.0)
        if args.duration is not None:
            opts.dwell_s = float(args.duration) / max(1, len(spec.measurement_points))
        rec = simulate_building_roving(spec, opts) if isinstance(opts, DroneOptions) else simulate_roving(spec, opts)
        if out.exists() and (out / "bag").exists():
            shutil.rmtree(out / "bag")
        out.mkdir(parents=True, exist_ok=True)
        write_roving_bag(rec, out / "bag")
    except (ValueError, OSError) as exc:
        print(f"shm-ros simulate: {exc}", file=sys.stderr)
        return 2
    dump_structure(spec, out / "structure.yaml")
    t = rec.truth
    dump({"scenario": args.scenario, "seed": opts.seed, "clock_offset_s": rec.clock_offset_s,
          "robot_mass_kg": getattr(opts, "robot_mass_kg", 0.0),
          "robot_modal_mass_fraction_mode1": rec.robot_modal_mass_fraction,
          "phases": [{"kind": k, "start_s": a, "end_s": b, "point": p} for k, a, b, p in rec.phases],
          "modes": [{"frequency_hz": float(t.frequencies_hz[j]), "damping_ratio": float(t.damping_ratios[j]),
                     "family": t.families[j] if t.families else "",
                     "shape": {s: float(t.shapes[i, j]) for i, s in enumerate(t.sensor_ids)}}
                    for j in range(t.frequencies_hz.size)]}, out / "truth.json")
    print(f"wrote {out / 'bag'}, {out / 'structure.yaml'}, {out / 'truth.json'} ({len(rec.phases)} phases)")
    return 0


def identify(args: argparse.Namespace, spec, cfg) -> int:
    from dataclasses import replace

    from shm_ros.core.roving.pipeline import RovingConfig, roving_modes
    from shm_ros.errors import ShmError
    from shm_ros.io.jsonio import dump
    from shm_ros.io.roving_bag import read_roving_bag

    try:
        bag = read_roving_bag(args.bag, spec)
        res = roving_modes(spec, bag.times_ns, bag.fs, bag.references, bag.roving, bag.buffer,
                           RovingConfig(identify=replace(cfg, uncertainty=False)))
    except ShmError as exc:
        print(f"shm-ros identify: {exc}", file=sys.stderr)
        return exc.exit_code
    for e in res.cut.errors():
        print(f"shm-ros identify: {args.bag}: {e}", file=sys.stderr)
    doc = {"windows": [], **res.to_dict()}
    doc["roving"]["positions"] = {**{s.id: [float(s.at["x"]), 0.0, 0.0] for s in spec.sensors if "x" in s.at},
                                  **{p.id: list(p.position) for p in spec.measurement_points
                                     if p.position is not None}}
    dump(doc, args.out)
    print(f"{len(res.cut.setups)} setups, {len(res.global_modes)} global modes, clock offset "
          f"{1e3 * res.clock_offset_s:.1f} ms; {res.cut.moving_samples} samples while moving left out -> {args.out}")
    return 0
