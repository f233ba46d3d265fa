"""`shm-ros`: one command line for the offline cores and the live node graph."""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys
from typing import NoReturn

from shm_ros import __version__
from shm_ros.commands import COMMANDS
from shm_ros.errors import ShmError


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (``shm-ros CMD: error: ...``), exit code 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The command line's parser; with ``command`` (a command's name, e.g. ``run``) that command's
    subparser only: each command's options import its core's configuration, and a process started
    for one command (a graph, a replay) need not import every other stage's numerics."""
    modules = [name for name in COMMANDS if command is None or name.rstrip("_") == command]
    parser = OneLineParser(
        prog="shm-ros",
        description="Structural health monitoring on ROS 2: recordings -> windows -> modes -> "
        "tracked modes -> calibrated model -> predictions -> missing physics.",
    )
    parser.add_argument("--version", action="version", version=f"shm-ros {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in modules or COMMANDS:
        module_name = f"shm_ros.commands.{name}"
        if importlib.util.find_spec(module_name) is None:
            continue  # stage not shipped in this build
        importlib.import_module(module_name).add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one command. An error the user can act on (:class:`shm_ros.errors.ShmError`) is printed as
    one line and exits with its code; any other exception is a bug and shows its traceback."""
    given = sys.argv[1:] if argv is None else argv
    parser = build_parser(given[0] if given else None)
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except ShmError as exc:
        print(f"shm-ros {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code


if __name__ == "__main__":
    sys.exit(main())
