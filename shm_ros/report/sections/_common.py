"""Helpers of the section builders: a figure with its data file, CSV/JSON writers, times."""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.io.jsonio import dump as jsonio_dump
from shm_ros.io.jsonio import to_jsonable
from shm_ros.report.document import Figure
from shm_ros.report.figures import save_figure

DPI = 100


def pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plain(x: Any) -> Any:
    """JSON-ready (numpy to Python, non-finite floats to None): the package's one JSON helper."""
    return to_jsonable(x)


def write_json(path: Path, obj: Any) -> Path:
    return jsonio_dump(obj, path)


def _csv_cell(v: Any) -> str:
    v = plain(v)
    if v is None:
        return ""
    if isinstance(v, float):
        return repr(v)
    return str(v)


def write_csv(path: Path, header: Sequence[str], rows: Iterable[Sequence[Any]]) -> Path:
    """Missing values (None, NaN) as empty cells, floats at full precision."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(list(header))
        for row in rows:
            w.writerow([_csv_cell(v) for v in row])
    return path


def figure_csv(fig: Any, fig_dir: Path, name: str, caption: str, header: Sequence[str],
               rows: Iterable[Sequence[Any]]) -> Figure:
    """Save ``fig`` as ``fig_dir/name.png`` and its numbers as ``fig_dir/name.csv``."""
    data = write_csv(fig_dir / f"{name}.csv", header, rows)
    png = save_figure(fig, fig_dir / f"{name}.png", dpi=DPI)
    return Figure(png, data, caption)


def figure_json(fig: Any, fig_dir: Path, name: str, caption: str, data: Any) -> Figure:
    """Save ``fig`` as ``fig_dir/name.png`` and its numbers as ``fig_dir/name.json``."""
    path = write_json(fig_dir / f"{name}.json", data)
    png = save_figure(fig, fig_dir / f"{name}.png", dpi=DPI)
    return Figure(png, path, caption)


def iso(t_s: float) -> str | None:
    """POSIX seconds as ISO 8601 UTC (None when not finite)."""
    if not math.isfinite(t_s):
        return None
    return datetime.fromtimestamp(t_s, tz=timezone.utc).isoformat().replace("+00:00", "Z")


def iso_ns(t_ns: int) -> str:
    return iso(t_ns / 1e9) or ""


def datetimes(times_s: Iterable[float]) -> list[datetime]:
    return [datetime.fromtimestamp(float(t), tz=timezone.utc) for t in times_s]


def short_time_axis(ax: Any) -> None:
    """Readable dates on a time axis of any span."""
    import matplotlib.dates as mdates

    loc = mdates.AutoDateLocator()
    ax.xaxis.set_major_locator(loc)
    ax.xaxis.set_major_formatter(mdates.ConciseDateFormatter(loc))
    ax.set_xlabel("time (UTC)")


def median_or_none(x: np.ndarray) -> float | None:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(np.median(x)) if x.size else None
