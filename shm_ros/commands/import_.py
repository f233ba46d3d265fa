"""`shm-ros import FILE... --out BAG`: recordings from other tools -> a bag of the recording layout
(docs/interfaces.md §1).

Formats (from the file name unless --format): CSV (.csv/.txt/.tsv; a header row of channel names or
--channels; --rate or a --time-column), NPY (.npy, (n_samples, n_channels); --rate, --channels),
CSMIP/COSMOS V2 strong-motion records (.V2, or a .zip of them; cm/s^2 converted to m/s^2; channel n
is named chan<n> unless --v2-names maps it), MiniSEED (.mseed; --scale for counts). Written as
AccelBlock messages (default) or per-sample sensor_msgs/Imu (--layout imu).

`shm-ros import opensees SCRIPT --parameters NAME=TAG,... --sensors ID=NODE:DOF,... --out S.yaml`:
runs the user's OpenSeesPy script once and writes a `kind: matrices` structure file (S.yaml and
S.npz: mass, stiffness and one stiffness part per OpenSees parameter the script declares), checked
against OpenSees's own eigenvalues (docs/structure_files.md). Needs the optional OpenSeesPy.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    from shm_ros.commands.checks import add_overwrite, finite_float, positive_float, positive_int

    p = sub.add_parser("import", help="convert CSV/NPY/V2/MiniSEED recordings into a bag (docs/interfaces.md §1)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("files", nargs="+", help="input files (all go into one bag)")
    p.add_argument("--out", required=True, help="bag to create (a new directory; see --overwrite)")
    add_overwrite(p)
    p.add_argument("--format", choices=("csv", "npy", "v2", "miniseed"), help="input format (default: by name)")
    p.add_argument("--rate", type=positive_float, help="sample rate, Hz (CSV without time column, NPY)")
    p.add_argument("--channels", help="comma-separated channel names (CSV columns to keep / NPY columns)")
    p.add_argument("--time-column", help="CSV column with sample times in s (epoch s when > 1e8)")
    p.add_argument("--start", help="time of the first sample: ISO 8601 UTC or epoch seconds (CSV, NPY)")
    p.add_argument("--units", default="m/s^2", help="units of the values: m/s^2 (default), g, cm/s^2, mm/s^2")
    p.add_argument("--scale", type=finite_float, help="MiniSEED: multiply samples by this (e.g. 1/sensitivity)")
    p.add_argument("--v2-names", help="V2: channel names, e.g. '1=g0,5=f1' (default chan<n>)")
    p.add_argument("--layout", choices=("block", "imu"), default="block",
                   help="AccelBlock messages (default) or one sensor_msgs/Imu per sample and channel")
    p.add_argument("--axis", choices=("x", "y", "z"), default="z", help="Imu layout: axis holding the value")
    p.add_argument("--prefix", default="", help="topic prefix, e.g. /site1")
    p.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    p.add_argument("--no-compress", action="store_true", help="do not zstd-compress MCAP chunks")
    p.add_argument("--block-s", type=positive_float, default=1.0, help="seconds per AccelBlock message (default 1)")
    o = p.add_argument_group("import opensees SCRIPT (a structure file from an OpenSeesPy model)")
    o.add_argument("--parameters", help="NAME=TAG,...: the OpenSees parameters (declared by the script) to update")
    o.add_argument("--sensors", help="ID=NODE:DOF,...: sensors at OpenSees nodes and 1-based DOFs")
    o.add_argument("--direction", default="vertical", choices=("vertical", "x", "y"), help="the sensors' direction")
    o.add_argument("--prior-std", type=positive_float, default=0.1,
                   help="std of the lognormal prior of each factor (mean 1)")
    o.add_argument("--name", help="structure name (default: the script's name)")
    o.add_argument("--modes", type=positive_int, default=5, help="modes checked against OpenSees's eigen (default 5)")
    p.set_defaults(func=run)


def run_opensees(args: argparse.Namespace) -> int:
    from shm_ros.commands.checks import input_file, output_file
    from shm_ros.io.opensees import OpenSeesImportError, import_opensees, parse_parameters, parse_sensors

    if len(args.files) != 2 or not args.parameters or not args.sensors:
        raise OpenSeesImportError("usage: shm-ros import opensees SCRIPT --parameters NAME=TAG,... "
                                  "--sensors ID=NODE:DOF,... --out S.yaml")
    input_file(args.files[1], "SCRIPT")
    output_file(args.out, "--out", args.overwrite)
    mats = import_opensees(args.files[1], parse_parameters(args.parameters), parse_sensors(args.sensors), args.out,
                           name=args.name, direction=args.direction, prior_std=args.prior_std, n_modes=args.modes)
    freqs = ", ".join(f"{f:.4g}" for f in mats.matrices_hz)
    print(f"{args.out}: kind matrices, {len(mats.dof_labels)} DOFs, parameters {', '.join(mats.terms)}; "
          f"modes {freqs} Hz (OpenSees eigen agrees to {abs(mats.matrices_hz / mats.opensees_hz - 1).max():.1e})")
    return 0


def run(args: argparse.Namespace) -> int:
    if args.files[0] == "opensees" and not Path(args.files[0]).exists():
        return run_opensees(args)
    from shm_ros.commands.checks import input_file, output_new
    from shm_ros.core.timeutil import ns_to_iso as iso_utc
    from shm_ros.errors import InputError
    from shm_ros.io.importers import parse_time, read_any, write_bag

    for f in args.files:
        input_file(f, "FILE")
    output_new(args.out, "--out", args.overwrite)
    if args.scale == 0:
        raise InputError("--scale must not be 0")
    parse_time(args.start, "--start")
    channels = [c.strip() for c in args.channels.split(",")] if args.channels else None
    v2_names = None
    try:
        if args.v2_names:
            v2_names = {}
            for item in args.v2_names.split(","):
                k, _, v = item.partition("=")
                v2_names[int(k)] = v.strip()
    except ValueError:
        raise InputError(f"--v2-names: expected e.g. '1=g0,5=f1', got {args.v2_names!r}") from None
    records = []
    for f in args.files:
        records += read_any(f, args.format, sample_rate_hz=args.rate, channels=channels,
                            time_column=args.time_column, start=args.start, units=args.units,
                            scale=args.scale, v2_channels=v2_names)
    summary = write_bag(records, args.out, layout=args.layout, prefix=args.prefix,
                        storage=args.storage, compress=not args.no_compress, block_s=args.block_s,
                        axis=args.axis, overwrite=args.overwrite)
    print(f"{summary['bag']}: {summary['messages']} messages on {', '.join(summary['topics'])}; "
          f"channels {', '.join(summary['channels'])}; {summary['samples']} samples from "
          f"{iso_utc(summary['start_ns'])} to {iso_utc(summary['last_ns'])}")
    return 0
