"""Finished bags of a batch, kept in its output folder so that a killed batch resumes where it stopped.

Each bag's job writes its result to ``OUT/.bags/<key>.json`` as soon as it is done (written to a
temporary file, then renamed: a job killed half-way leaves nothing). The key covers what the result
depends on: the bag's path and files (names, sizes, modification times), the structure file's
content and the batch settings; a bag that changed, or a batch run with other settings, is
identified again. A restarted batch loads the finished bags and runs the others only; a batch that
has written its outputs removes the folder. The files are in the typed, data-only encoding of
:mod:`shm_ros.io.checkpoint` (never a pickle: reading a crafted file cannot run code; a file that does
not decode is redone).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from dataclasses import asdict
from pathlib import Path

from shm_ros.batch.archive import ArchiveBag
from shm_ros.batch.jobs import BagResult, BatchSettings, identify_bag
from shm_ros.io.checkpoint import CheckpointError, Codec
from shm_ros.io.store import CHECKPOINT_CLASSES

FOLDER = ".bags"
_CODEC = Codec([BagResult, *CHECKPOINT_CLASSES])


def _files(bag: Path) -> list[tuple[str, int, int]]:
    paths = sorted(p for p in bag.rglob("*") if p.is_file()) if bag.is_dir() else [bag]
    return [(str(p.relative_to(bag) if bag.is_dir() else p.name), p.stat().st_size, p.stat().st_mtime_ns)
            for p in paths]


def key(item: ArchiveBag, settings: BatchSettings) -> str:
    """What the bag's result depends on, hashed."""
    doc = {"bag": str(Path(item.bag).resolve()), "files": _files(Path(item.bag)),
           "structure": hashlib.sha256(Path(item.structure).read_bytes()).hexdigest(),
           "settings": asdict(settings)}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:32]


def path_for(out: str | Path, item: ArchiveBag, settings: BatchSettings) -> Path:
    return Path(out) / FOLDER / f"{key(item, settings)}.json"


def load(path: Path) -> BagResult | None:
    """The finished bag's result, or None (not finished, or unreadable: then it is redone)."""
    try:
        result = _CODEC.loads(path.read_bytes())
    except (OSError, CheckpointError):
        return None
    return result if isinstance(result, BagResult) else None


def identify_bag_kept(job: tuple[ArchiveBag, BatchSettings, str]) -> BagResult:
    """:func:`shm_ros.batch.jobs.identify_bag`, its result kept at ``path`` (atomically)."""
    item, settings, path = job
    result = identify_bag((item, settings))
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(f"{target.name}.{os.getpid()}.tmp")
    tmp.write_bytes(_CODEC.dumps(result))
    os.replace(tmp, target)
    return result


def clear(out: str | Path) -> None:
    """Remove the kept results (the batch has written its outputs)."""
    shutil.rmtree(Path(out) / FOLDER, ignore_errors=True)
