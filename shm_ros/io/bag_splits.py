"""A bag written in splits that survive the writer's crashes: one rosbag2 bag of several files.

A recorder that restarts (after a crash, or a stop and a new start) never refuses its output bag
and never truncates it: each start writes a new split. Split ``k`` of the bag ``out`` is written
as a bag of its own in ``out/out_<k>/``, every message flushed to disk as it is written (MCAP: one
chunk per write; sqlite3: one commit), so a process killed at any instant loses at most the
message it was writing. When the split is closed its file moves to ``out/out_<k>.mcap`` and
``out/metadata.yaml`` lists it with the earlier ones: the bag reads as one bag.

On open, what a killed writer left is taken up first: a split that was closed but not yet merged
is merged; a split cut short (no footer, no metadata) is read for every complete message (the
damaged-bag readers of :mod:`shm_ros.io.sources`) and written again as a complete split.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any

import yaml

from shm_ros.io.atomic import atomic_path
from shm_ros.io.bags import BagWriter
from shm_ros.io.errors import BagError
from shm_ros.io.sources.base import BagMessage

INFO = "rosbag2_bagfile_information"


def _split_dirs(path: Path) -> list[tuple[int, Path]]:
    """The unmerged splits of the bag ``path``: (index, folder), by index."""
    out = []
    for entry in path.iterdir():
        if entry.is_dir() and entry.name.startswith(f"{path.name}_"):
            tail = entry.name[len(path.name) + 1:]
            if tail.isdigit():
                out.append((int(tail), entry))
    return sorted(out)


def read_info(path: Path) -> dict[str, Any] | None:
    """``rosbag2_bagfile_information`` of the bag folder ``path``; None when it has none."""
    meta = path / "metadata.yaml"
    if not meta.exists():
        return None
    doc = yaml.safe_load(meta.read_text())
    if not isinstance(doc, dict) or not isinstance(doc.get(INFO), dict):
        raise BagError(f"{meta}: not a rosbag2 metadata file")
    return doc[INFO]


def _merge(total: dict[str, Any] | None, part: dict[str, Any]) -> dict[str, Any]:
    """The bag's information with one more split (its files, counts and time span)."""
    if total is None:
        return dict(part)
    names = list(total.get("relative_file_paths") or [])
    new = [f for f in part.get("relative_file_paths") or [] if f not in names]
    if not new:  # merged before (a crash after the merge): nothing to add
        return total
    out = dict(total)
    out["relative_file_paths"] = names + new
    out["files"] = list(total.get("files") or []) + [f for f in part.get("files") or [] if f["path"] in new]
    counts = {t["topic_metadata"]["name"]: t for t in total.get("topics_with_message_count") or []}
    for t in part.get("topics_with_message_count") or []:
        name = t["topic_metadata"]["name"]
        if name in counts:
            counts[name] = {**counts[name], "message_count": counts[name]["message_count"] + t["message_count"]}
        else:
            counts[name] = t
    out["topics_with_message_count"] = list(counts.values())
    out["message_count"] = int(total.get("message_count", 0)) + int(part.get("message_count", 0))
    spans = [(int(f["starting_time"]["nanoseconds_since_epoch"]), int(f["duration"]["nanoseconds"]))
             for f in out["files"] if int(f.get("message_count", 0))]
    if spans:
        start = min(s for s, _ in spans)
        out["starting_time"] = {"nanoseconds_since_epoch": start}
        out["duration"] = {"nanoseconds": max(s + d for s, d in spans) - start}
    return out


def _write_info(path: Path, info: dict[str, Any]) -> None:
    with atomic_path(path / "metadata.yaml") as tmp:
        tmp.write_text(yaml.safe_dump({INFO: info}, sort_keys=False))


def _finish(path: Path, split: Path) -> None:
    """Move a closed split's file into the bag and list it there (safe to repeat after a crash)."""
    part = read_info(split)
    if part is None:
        raise BagError(f"{split}: a split without metadata.yaml cannot be listed in {path}")
    for name in part.get("relative_file_paths") or []:
        if (split / name).exists():
            os.replace(split / name, path / name)
    _write_info(path, _merge(read_info(path), part))
    shutil.rmtree(split)


class SplitBagWriter:
    """Writes messages as CDR into a new split of the bag at ``path`` (see the module's text)."""

    def __init__(self, path: str | Path, storage: str = "mcap") -> None:
        self.path = Path(path)
        self.storage = storage
        self.recovered: list[str] = []  # what the opening found and took up, for the log
        self.split: Path | None = None
        self._writer: BagWriter | None = None

    def open(self) -> SplitBagWriter:
        if self.path.exists() and not self.path.is_dir():
            raise BagError(f"{self.path}: exists and is not a bag folder")
        self.path.mkdir(parents=True, exist_ok=True)
        for _, split in _split_dirs(self.path):
            self._recover(split)
        index = self._next_index()
        self.split = self.path / f"{self.path.name}_{index}"
        self._writer = BagWriter(self.split, storage=self.storage).__enter__()
        return self

    def _next_index(self) -> int:
        used = [k for k, _ in _split_dirs(self.path)]
        info = read_info(self.path) or {}
        for name in info.get("relative_file_paths") or []:
            tail = Path(name).stem[len(self.path.name) + 1:]
            if tail.isdigit():
                used.append(int(tail))
        return max(used, default=-1) + 1

    def _recover(self, split: Path) -> None:
        if read_info(split) is not None:  # closed, not yet merged
            _finish(self.path, split)
            self.recovered.append(f"{split.name}: closed split merged")
            return
        from shm_ros.io.sources import open_source

        files = [f for f in split.iterdir() if f.suffix in (".mcap", ".db3")]
        if not files or all(f.stat().st_size == 0 for f in files):
            shutil.rmtree(split)
            return
        try:
            source = open_source(split)
            types = source.topics()
        except BagError as exc:
            self.recovered.append(f"{split.name}: unreadable, set aside ({exc})")
            os.replace(split, split.with_name(f".{split.name}.unreadable"))
            return
        messages: list[BagMessage] = []
        problem = ""
        try:
            for m in source.messages():
                messages.append(m)
        except BagError as exc:  # where the killed writer stopped: everything before it is kept
            problem = str(exc)
        tmp = split.with_name(f"{split.name}.recovered")
        if tmp.exists():
            shutil.rmtree(tmp)
        writer = BagWriter(tmp, storage=self.storage)
        with writer:
            for m in messages:
                writer.write_cdr(m.topic, types.get(m.topic, m.msgtype), m.receive_ns, m.data)
        # the recovered copy takes the split's name: rename its folder and file
        final = tmp / f"{split.name}{_suffix(self.storage)}"
        os.replace(tmp / f"{tmp.name}{_suffix(self.storage)}", final)
        info = _rename(read_info(tmp) or {}, f"{tmp.name}{_suffix(self.storage)}", final.name)
        _write_info(tmp, info)
        shutil.rmtree(split)
        os.replace(tmp, split)
        _finish(self.path, split)
        self.recovered.append(f"{split.name}: cut short, {len(messages)} complete messages kept"
                              + (f" ({problem})" if problem else ""))

    def write_cdr(self, topic: str, msgtype: str, t_ns: int, data: bytes) -> None:
        """Write one message and flush it to disk."""
        if self._writer is None:
            raise BagError(f"{self.path}: write before open() or after close()")
        self._writer.write_cdr(topic, msgtype, t_ns, data)
        self._writer.flush()

    def close(self) -> None:
        """Close the split (footer, metadata) and merge it into the bag."""
        writer, self._writer = self._writer, None
        if writer is None or self.split is None:
            return
        writer.__exit__(None, None, None)
        _finish(self.path, self.split)

    def __enter__(self) -> SplitBagWriter:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()


def _suffix(storage: str) -> str:
    return ".mcap" if storage == "mcap" else ".db3"


def _rename(info: dict[str, Any], old: str, new: str) -> dict[str, Any]:
    info = dict(info)
    info["relative_file_paths"] = [new if p == old else p for p in info.get("relative_file_paths") or []]
    info["files"] = [{**f, "path": new} if f.get("path") == old else f for f in info.get("files") or []]
    return info
