"""Writers of the project's public formats: structure YAML (docs/structure_files.md), tracked-modes
CSV (docs/interfaces.md §4), bags through the documented importer (``shm_ros.io.importers``) and
truth.json (the generator's own record of what was put in)."""

from __future__ import annotations

import csv
import json
import math
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import numpy as np
import yaml

EPOCH = datetime(2025, 1, 1, tzinfo=timezone.utc)


def iso(t_s: float, start: datetime = EPOCH) -> str:
    """Seconds after ``start`` as ISO 8601 UTC with milliseconds (docs/interfaces.md conventions)."""
    t = start + timedelta(seconds=float(t_s))
    return t.strftime("%Y-%m-%dT%H:%M:%S.") + f"{t.microsecond // 1000:03d}Z"


def epoch_ns(t_s: float, start: datetime = EPOCH) -> int:
    return int(round((start.timestamp() + float(t_s)) * 1e9))


def _plain(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return _plain(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, np.integer):
        return int(x)
    return x


def write_yaml(doc: dict, path: Path) -> Path:
    path.write_text(yaml.safe_dump(_plain(doc), sort_keys=False))
    return path


def write_truth(doc: dict, path: Path) -> Path:
    path.write_text(json.dumps(_plain(doc), indent=1, allow_nan=False))
    return path


def write_table(path: Path, times_s: np.ndarray, columns: dict[str, np.ndarray], start: datetime = EPOCH) -> Path:
    """A tracked-modes table: ``time`` then the given columns
    NaN cells are written empty."""
    names = list(columns)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time", *names])
        for i, t in enumerate(times_s):
            row = [iso(t, start)]
            for n in names:
                v = float(columns[n][i])
                row.append("" if not math.isfinite(v) else f"{v:.6g}")
            w.writerow(row)
    return path


def write_event_bag(path: Path, events: list[tuple[float, float, list[str], np.ndarray]]) -> dict:
    """One AccelBlock stream per event (time s, rate Hz, channel names, samples (N, c) m/s^2)."""
    from shm_ros.io.importers import ImportedRecord, write_bag

    records = [ImportedRecord(channel_names=names, samples=np.asarray(x, dtype=float), sample_rate_hz=rate,
                              start_ns=epoch_ns(t), source=f"event {k}")
               for k, (t, rate, names, x) in enumerate(events)]
    return write_bag(records, path)
