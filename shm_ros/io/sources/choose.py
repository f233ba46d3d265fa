"""Which back end reads a bag, decided from what the bag is before anything is read.

* a directory with ``metadata.yaml``: its storage id and compression mode decide. MCAP files
  whose summary is usable go through chunks (:mod:`.mcap_chunks`), unless their messages are
  compressed one by one or not chunked (``rosbags``); MCAP files cut short or with a damaged
  summary are salvaged record by record. sqlite3 files are read in receive order
  (:mod:`.sqlite_rows`), or row by row in written order when a file is cut short. A bag
  compressed file by file, or of another storage, goes to ``rosbags``.
* a directory without ``metadata.yaml`` (a recorder that was killed) or with one that cannot be
  parsed: its ``.mcap`` / ``.db3`` files are read directly, with a warning saying so.
* a single file: by its magic number (MCAP, SQLite), else ``rosbags`` (ROS 1 bags).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from shm_ros.io.errors import BagError
from shm_ros.io.sources.base import MessageSource
from shm_ros.io.sources.mcap_chunks import MAGIC as MCAP_MAGIC
from shm_ros.io.sources.mcap_chunks import McapChunkSource, inspect_mcap
from shm_ros.io.sources.rosbags_reader import RosbagsSource
from shm_ros.io.sources.salvage import McapRecordSource, salvage_sqlite
from shm_ros.io.sources.sqlite_rows import MessageCompression, RowOrder, SqliteSource, sqlite_damage

SQLITE_MAGIC = b"SQLite format 3\x00"


@dataclass(frozen=True)
class Metadata:
    """What ``metadata.yaml`` says about how the bag is stored."""

    storage: str
    files: list[Path]
    compression_mode: str  # "" (none), "message" or "file"
    compression_format: str


def open_source(path: str | Path) -> MessageSource:
    """The back end that reads the bag at ``path``; :class:`BagError` when there is none."""
    path = Path(path)
    if not path.exists():
        raise BagError(f"{path}: no such bag")
    if path.is_file():
        return _open_file(path)
    meta_file = path / "metadata.yaml"
    if not meta_file.exists():
        return _open_files(path, f"{path}: no metadata.yaml (a recorder that did not finish): "
                                 "read from its storage files directly")
    meta = _read_metadata(meta_file)
    if meta is None:
        return _open_files(path, f"{meta_file}: cannot be parsed: read from the bag's storage files directly")
    if meta.compression_mode == "file" or not meta.files or not all(f.exists() for f in meta.files):
        return RosbagsSource(path)  # decompresses whole files; reports missing ones
    per_message = meta.compression_mode == "message"
    if meta.storage == "mcap":
        if per_message and meta.compression_format != "zstd":
            return RosbagsSource(path)
        return _open_mcap(path, meta.files, note="", has_metadata=True, message_zstd=per_message)
    if meta.storage == "sqlite3":
        if per_message and meta.compression_format != "zstd":
            return RosbagsSource(path)
        return _open_sqlite(path, meta.files, MessageCompression.ZSTD if per_message else MessageCompression.NONE)
    return RosbagsSource(path)


def _read_metadata(meta_file: Path) -> Metadata | None:
    import yaml

    try:
        doc: Any = yaml.safe_load(meta_file.read_text())
    except (yaml.YAMLError, UnicodeDecodeError):  # a half-written file
        return None
    info = doc.get("rosbag2_bagfile_information") if isinstance(doc, dict) else None
    if not isinstance(info, dict):
        return None
    mode = str(info.get("compression_mode") or "").lower()
    return Metadata(
        storage=str(info.get("storage_identifier") or ""),
        files=[meta_file.parent / str(p) for p in info.get("relative_file_paths") or []],
        compression_mode="" if mode == "none" else mode,
        compression_format=str(info.get("compression_format") or "").lower(),
    )


def _magic(f: Path, n: int) -> bytes:
    with open(f, "rb") as fh:
        return fh.read(n)


def _open_file(f: Path) -> MessageSource:
    head = _magic(f, 16)
    if head.startswith(MCAP_MAGIC):
        return _open_mcap(f, [f], note="", has_metadata=False)
    if head == SQLITE_MAGIC:
        return _open_sqlite(f, [f], MessageCompression.DETECT, note=f"{f}: a storage file without its "
                            "metadata.yaml: read row by row", order=RowOrder.WRITTEN)
    return RosbagsSource(f)


def _open_files(path: Path, note: str) -> MessageSource:
    mcaps = sorted(path.glob("*.mcap"))
    dbs = sorted(path.glob("*.db3"))
    if mcaps:
        return _open_mcap(path, mcaps, note=note, has_metadata=False, message_zstd=None)
    if dbs:
        return _open_sqlite(path, dbs, MessageCompression.DETECT, note=note, order=RowOrder.WRITTEN)
    raise BagError(f"{path}: neither metadata.yaml nor MCAP or sqlite3 files to read")


def _open_mcap(path: Path, files: list[Path], note: str, has_metadata: bool,
               message_zstd: bool | None = False) -> MessageSource:
    """``message_zstd`` None: not known (no metadata), taken as not compressed."""
    infos = [inspect_mcap(f) for f in files]
    problems = [i.problem for i in infos if i.problem]
    if problems:
        why = "; ".join(problems)
        return McapRecordSource(path, files, note=f"{note}; {why}" if note else why,
                                message_zstd=bool(message_zstd))
    if message_zstd or any(i.unchunked or not i.cdr for i in infos):
        if has_metadata:
            return RosbagsSource(path, note)
        return McapRecordSource(path, files, note=note, message_zstd=bool(message_zstd))
    return McapChunkSource(path, infos, note=note)


def _open_sqlite(path: Path, files: list[Path], compression: MessageCompression, note: str = "",
                 order: RowOrder = RowOrder.RECEIVED) -> MessageSource:
    damage = "; ".join(d for d in (sqlite_damage(f) for f in files) if d)
    if damage:
        why = f"{damage}: read row by row up to the damage"
        return salvage_sqlite(path, files, note=f"{note}; {why}" if note else why, damage=damage)
    return SqliteSource(path, files, order, compression, note=note)
