"""Checks of command-line options, run before any work: values, input paths, output paths.

Value checks are argparse ``type=`` functions (``positive_float``, ``count`` ...): a value outside
the documented range is refused by the parser with a one-line message and exit code 2. Path checks
(:func:`input_file`, :func:`input_path`, :func:`output_dir`, :func:`output_file`) raise
:class:`~shm_ros.errors.InputError` naming the option; a command calls them first, so a bad path
costs nothing and creates nothing.

Outputs: :class:`Outputs` stages a command's files in a temporary folder next to ``--out`` and moves
them into place when the command succeeds (each file or sub-folder replaced whole, so a rerun never
leaves stale files of an earlier run in a sub-folder); a failed command leaves ``--out`` as it was.
``--out`` must be new or empty unless ``--overwrite`` is given.
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import TypeVar

from shm_ros.errors import InputError
from shm_ros.io.atomic import DiskFullError, partial_name, replace_entry

N = TypeVar("N", int, float)

__all__ = ["Outputs", "add_overwrite", "count", "finite_float", "input_file", "input_path", "nonneg_float",
           "nonneg_int", "output_dir", "output_file", "output_new", "positive_float", "positive_int"]


# -- values --------------------------------------------------------------------------------------

def finite_float(text: str) -> float:
    """A finite number (``nan`` and ``inf`` refused)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return v


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


def _at_least(parse: Callable[[str], N], low: float, name: str, *, strict: bool = False) -> Callable[[str], N]:
    """``parse`` then refuse a value below ``low`` (or equal to it when ``strict``)."""
    def check(text: str) -> N:
        v = parse(text)
        if v < low or (strict and v == low):
            raise argparse.ArgumentTypeError(f"must be {'>' if strict else '>='} {low:g}, got {text!r}")
        return v
    check.__name__ = name
    return check


positive_float = _at_least(finite_float, 0, "positive_float", strict=True)
nonneg_float = _at_least(finite_float, 0, "nonneg_float")
positive_int = _at_least(_integer, 1, "positive_int")
nonneg_int = _at_least(_integer, 0, "nonneg_int")
count = positive_int


def min_float(low: float) -> Callable[[str], float]:
    """A finite number >= ``low`` (e.g. a window of at least one second)."""
    return _at_least(finite_float, low, f"number>={low:g}")


# -- paths ---------------------------------------------------------------------------------------

def input_file(path: str | None, option: str, kind: str = "file") -> None:
    """``path`` (if given) must be an existing, readable file (``kind`` names it in the message)."""
    if path is None:
        return
    p = Path(path)
    if not p.exists():
        raise InputError(f"{option} {path}: no such {kind}")
    if p.is_dir():
        raise InputError(f"{option} {path}: is a directory, expected a file")
    if not os.access(p, os.R_OK):
        raise InputError(f"{option} {path}: not readable")


def input_path(path: str | None, option: str) -> None:
    """``path`` (if given) must exist (a file or a folder, e.g. a bag) and be readable."""
    if path is None:
        return
    p = Path(path)
    if not p.exists():
        raise InputError(f"{option} {path}: no such file or directory")
    if not os.access(p, os.R_OK):
        raise InputError(f"{option} {path}: not readable")


def input_dir(path: str | None, option: str) -> None:
    """``path`` (if given) must be an existing folder."""
    if path is None:
        return
    input_path(path, option)
    if not Path(path).is_dir():
        raise InputError(f"{option} {path}: is a file, expected a directory")


def _writable_parent(p: Path, option: str) -> None:
    """The nearest existing ancestor of ``p`` must be a folder we may write in."""
    anc = p.parent
    while not anc.exists():
        if anc.parent == anc:
            break
        anc = anc.parent
    if not anc.is_dir():
        raise InputError(f"{option} {p}: {anc} is a file, not a directory")
    if not os.access(anc, os.W_OK | os.X_OK) or os.statvfs(anc).f_flag & os.ST_RDONLY:
        raise InputError(f"{option} {p}: cannot write in {anc} (permission denied or read-only)")


def output_dir(path: str, option: str = "--out", overwrite: bool = False) -> None:
    """``path`` must be a new or empty folder (any folder with ``overwrite``) we can create and write."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputError(f"{option} {path}: is a file, expected a directory")
    if p.is_dir():
        if any(not e.name.startswith(partial_name(p)) for e in p.iterdir()) and not overwrite:
            raise InputError(f"{option} {path}: directory is not empty (give --overwrite to replace its outputs)")
        if not os.access(p, os.W_OK | os.X_OK):
            raise InputError(f"{option} {path}: cannot write in it (permission denied)")
    _writable_parent(p.resolve(), option)


def output_file(path: str, option: str = "--out", overwrite: bool = False) -> None:
    """``path`` must be a new file (an existing one with ``overwrite``) in a folder we can write."""
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{option} {path}: is a directory, expected a file name")
    if p.exists() and not overwrite:
        raise InputError(f"{option} {path}: file exists (give --overwrite to replace it)")
    _writable_parent(p.resolve(), option)


def output_new(path: str, option: str = "--out", overwrite: bool = False) -> None:
    """``path`` (a file or a folder the command creates whole, e.g. a bag) must not exist unless
    ``overwrite``; its folder must be writable."""
    p = Path(path)
    if p.exists() and not overwrite:
        raise InputError(f"{option} {path}: exists (give --overwrite to replace it)")
    _writable_parent(p.resolve(), option)


def add_overwrite(p: argparse.ArgumentParser) -> None:
    p.add_argument("--overwrite", action="store_true",
                   help="replace the outputs of an earlier run in --out (default: --out must be new or empty)")


# -- staged outputs ------------------------------------------------------------------------------

class Outputs:
    """A staging folder for a command's outputs (module docstring). ``with Outputs(out) as stage:``
    write under ``stage``; on success every entry of ``stage`` replaces the same name in ``out``."""

    def __init__(self, out: str | Path) -> None:
        self.out = Path(out)
        self.stage: Path | None = None

    def __enter__(self) -> Path:
        self.out.parent.mkdir(parents=True, exist_ok=True)
        self.stage = Path(tempfile.mkdtemp(prefix=partial_name(self.out), dir=self.out.parent))
        return self.stage

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        assert self.stage is not None
        try:
            if kind is None:
                self.commit()
        finally:
            shutil.rmtree(self.stage, ignore_errors=True)

    def path(self, name: str) -> Path:
        """Where ``name`` ends up (for messages and reports written before the commit)."""
        return self.out / name

    def commit(self) -> None:
        assert self.stage is not None
        try:
            self.out.mkdir(parents=True, exist_ok=True)
            for entry in sorted(self.stage.iterdir()):
                replace_entry(entry, self.out / entry.name)
        except OSError as exc:
            if exc.errno == 28:  # ENOSPC
                raise DiskFullError(28, f"{self.out}: no space left on the device") from exc
            raise
