"""The tracked-modes table (docs/interfaces.md §4): CSV <-> :class:`ModalObservations`.

One row per window; a ``time`` column (ISO 8601 or seconds); ``mode<k>_hz`` columns (k = 1, 2, ...);
optional ``mode<k>_damping`` and ``mode<k>_shape_<sensor_id>``; every other column is a covariate.
Empty cells mean the mode was not found in that window.

Reading is tolerant of bad records: an unparsable cell becomes missing and a row with an unreadable
time is skipped, each with a note naming the file, row and column (``ModalObservations.notes``).
Structural problems (no time column, no mode columns, a file that is not CSV) raise
:class:`TableError` naming the file.
"""

from __future__ import annotations

import csv
import math
import re
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from shm_ros.core.observations import ModalObservations
from shm_ros.errors import InputError

_HZ = re.compile(r"^mode(\d+)_hz$")
_DAMP = re.compile(r"^mode(\d+)_damping$")
_SHAPE = re.compile(r"^mode(\d+)_shape_(.+)$")


class TableError(InputError):
    """A tracked-modes table that cannot be used; the message names the file (and column)."""


def _parse_time(cell: str) -> tuple[float, str]:
    cell = cell.strip()
    try:
        return float(cell), "seconds"
    except ValueError:
        pass
    text = cell[:-1] + "+00:00" if cell.endswith(("Z", "z")) else cell
    dt = datetime.fromisoformat(text)
    if dt.tzinfo is None:
        dt = dt.replace(tzinfo=timezone.utc)
    return dt.timestamp(), "iso"


def parse_time(cell: str) -> float:
    """Seconds (POSIX seconds for ISO 8601, UTC when no zone is given) of a time cell."""
    return _parse_time(cell)[0]


def _number(cell: str | None) -> float:
    if cell is None:
        return math.nan
    cell = cell.strip()
    if cell == "" or cell.lower() in ("nan", "null", "none", "na"):
        return math.nan
    return float(cell)


def read_tracked_modes(path: str | Path) -> ModalObservations:
    """Read a tracked-modes CSV into :class:`ModalObservations` (see the module docstring)."""
    path = Path(path)
    if not path.is_file():
        raise TableError(f"{path}: no such file")
    try:
        with path.open(newline="", encoding="utf-8-sig") as fh:
            rows = list(csv.reader(fh))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise TableError(f"{path}: not a readable CSV file ({exc})") from exc
    rows = [r for r in rows if any(c.strip() for c in r)]
    if not rows:
        raise TableError(f"{path}: empty table")
    header = [h.strip() for h in rows[0]]
    if "time" not in header:
        raise TableError(f"{path}: no 'time' column (columns: {header})")
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise TableError(f"{path}: duplicated column(s) {dup}")
    modes: dict[int, int] = {}
    damp: dict[int, int] = {}
    shapes: dict[tuple[int, str], int] = {}
    sensors: list[str] = []
    cov_cols: dict[str, int] = {}
    for j, h in enumerate(header):
        if h == "time":
            continue
        if m := _HZ.match(h):
            modes[int(m.group(1))] = j
        elif m := _DAMP.match(h):
            damp[int(m.group(1))] = j
        elif m := _SHAPE.match(h):
            k, sid = int(m.group(1)), m.group(2)
            shapes[(k, sid)] = j
            if sid not in sensors:
                sensors.append(sid)
        else:
            cov_cols[h] = j
    if not modes:
        raise TableError(f"{path}: no 'mode<k>_hz' column (columns: {header})")
    orphan = sorted(({k for k, _ in shapes} | set(damp)) - set(modes))
    notes: list[str] = []
    if orphan:
        notes.append(f"{path}: shape/damping columns of mode(s) {orphan} without mode<k>_hz "
                     "are ignored")
    numbers = sorted(modes)
    t_col = header.index("time")
    times, freqs, dmps, shps = [], [], [], []
    covs: dict[str, list[float]] = {c: [] for c in cov_cols}
    kinds = set()
    for r_i, row in enumerate(rows[1:], start=2):
        row = row + [""] * (len(header) - len(row))
        if len(row) > len(header):
            notes.append(f"{path}: row {r_i} has {len(row)} cells for {len(header)} columns; "
                         "extra cells ignored")
        try:
            t, kind = _parse_time(row[t_col])
        except ValueError:
            notes.append(f"{path}: row {r_i}: unreadable time {row[t_col]!r}; row skipped")
            continue
        kinds.add(kind)

        def num(j: int, col: str, row: list[str] = row, r_i: int = r_i) -> float:
            try:
                v = _number(row[j])
            except ValueError:
                notes.append(f"{path}: row {r_i}, column '{col}': not a number {row[j]!r}; "
                             "treated as missing")
                return math.nan
            if not math.isfinite(v):
                return math.nan
            return v

        f_row = [num(modes[k], f"mode{k}_hz") for k in numbers]
        for i, k in enumerate(numbers):
            if math.isfinite(f_row[i]) and f_row[i] <= 0:
                notes.append(f"{path}: row {r_i}, column 'mode{k}_hz': frequency {f_row[i]} <= 0; "
                             "treated as missing")
                f_row[i] = math.nan
        times.append(t)
        freqs.append(f_row)
        dmps.append([num(damp[k], f"mode{k}_damping") if k in damp else math.nan for k in numbers])
        shps.append([[num(shapes[(k, s)], f"mode{k}_shape_{s}") if (k, s) in shapes else math.nan
                      for s in sensors] for k in numbers])
        for c, j in cov_cols.items():
            covs[c].append(num(j, c))
    if not times:
        raise TableError(f"{path}: no usable rows")
    if len(kinds) > 1:
        raise TableError(f"{path}: column 'time' mixes ISO 8601 stamps and seconds")
    order = np.argsort(np.asarray(times), kind="stable")
    if np.any(np.diff(np.asarray(times)) < 0):
        notes.append(f"{path}: rows are not in time order; sorted by time")
    return ModalObservations(
        times=np.asarray(times)[order], mode_numbers=numbers,
        frequencies_hz=np.asarray(freqs, dtype=float)[order],
        shapes=np.asarray(shps, dtype=float)[order] if sensors else None,
        sensor_ids=sensors,
        damping=np.asarray(dmps, dtype=float)[order] if damp else None,
        covariates={c: np.asarray(v, dtype=float)[order] for c, v in covs.items()},
        notes=notes, time_kind=kinds.pop())


def _fmt(v: float) -> str:
    return "" if not math.isfinite(v) else repr(float(v))


def write_tracked_modes(path: str | Path, obs: ModalObservations) -> None:
    """Write :class:`ModalObservations` as a tracked-modes CSV (missing values as empty cells)."""
    path = Path(path)
    header = ["time"]
    for k in obs.mode_numbers:
        header.append(f"mode{k}_hz")
        if obs.damping is not None:
            header.append(f"mode{k}_damping")
        if obs.shapes is not None:
            header += [f"mode{k}_shape_{s}" for s in obs.sensor_ids]
    header += list(obs.covariates)
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for i in range(obs.n_windows):
            if obs.time_kind == "iso":
                t = datetime.fromtimestamp(float(obs.times[i]), tz=timezone.utc)
                row = [t.isoformat().replace("+00:00", "Z")]
            else:
                row = [_fmt(obs.times[i])]
            for k in range(obs.n_modes):
                row.append(_fmt(obs.frequencies_hz[i, k]))
                if obs.damping is not None:
                    row.append(_fmt(obs.damping[i, k]))
                if obs.shapes is not None:
                    row += [_fmt(v) for v in obs.shapes[i, k]]
            row += [_fmt(v[i]) for v in obs.covariates.values()]
            w.writerow(row)
