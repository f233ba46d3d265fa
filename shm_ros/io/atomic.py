"""Atomic writes: a file or folder appears complete under its name, or not at all.

``atomic_path(path)`` yields a temporary name in the same folder; when the block ends without an
error the temporary file or folder is renamed onto ``path`` (``os.replace``: atomic on one file
system), otherwise it is removed. ``staged_path(path)`` does the same for writers that create their
own folder and name files after it (a bag writer): it yields ``<temporary folder>/<name>``. A crash
leaves at most a ``.<name>.partial-*`` entry, never a half-written ``path``. A full disk
(``ENOSPC``) raises :class:`DiskFullError` naming the path and leaves what was there before untouched.
"""

from __future__ import annotations

import errno
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from shm_ros.errors import ShmError

__all__ = ["DiskFullError", "atomic_path", "partial_name", "replace_entry", "staged_path"]


class DiskFullError(ShmError, OSError):
    """No space left while writing an output; what was written before is kept."""


def partial_name(path: Path) -> str:
    """Prefix of the temporary names next to ``path``."""
    return f".{path.name}.partial-"


def _remove(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p, ignore_errors=True)
    else:
        p.unlink(missing_ok=True)


def _disk_full(exc: OSError, path: Path) -> None:
    if exc.errno == errno.ENOSPC:
        raise DiskFullError(errno.ENOSPC, f"{path}: no space left on the device; nothing of it was "
                            "written and earlier outputs are kept") from exc


@contextmanager
def atomic_path(path: str | Path, directory: bool = False) -> Iterator[Path]:
    """A temporary path next to ``path`` (a new empty folder when ``directory``), renamed onto
    ``path`` on success; an existing folder ``path`` is replaced as a whole."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if directory:
        tmp = Path(tempfile.mkdtemp(prefix=partial_name(path), dir=path.parent))
    else:
        fd, name = tempfile.mkstemp(prefix=partial_name(path), dir=path.parent)
        os.close(fd)
        tmp = Path(name)
    try:
        yield tmp
        replace_entry(tmp, path)
    except OSError as exc:
        _remove(tmp)
        _disk_full(exc, path)
        raise
    except BaseException:
        _remove(tmp)
        raise


@contextmanager
def staged_path(path: str | Path) -> Iterator[Path]:
    """``<temporary folder next to path>/<path's name>`` (not created), moved onto ``path`` on success."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    holder = Path(tempfile.mkdtemp(prefix=partial_name(path), dir=path.parent))
    try:
        yield holder / path.name
        replace_entry(holder / path.name, path)
    except OSError as exc:
        _disk_full(exc, path)
        raise
    finally:
        shutil.rmtree(holder, ignore_errors=True)


def replace_entry(src: Path, dest: Path) -> None:
    """Move ``src`` onto ``dest``; a folder at ``dest`` is removed first (a file is replaced atomically)."""
    if dest.is_dir() and not dest.is_symlink():
        old = dest.with_name(partial_name(dest) + "old")
        _remove(old)
        os.replace(dest, old)
        os.replace(src, dest)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(src, dest)
