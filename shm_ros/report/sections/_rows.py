"""A section made of one table of records (the stages whose results have no type of their own yet)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from shm_ros.report.document import Section, Table
from shm_ros.report.sections._common import write_csv


def rows_section(key: str, title: str, intro: str, rows: list[dict[str, Any]], notes: list[str],
                 fig_dir: Path) -> Section:
    """``rows`` as a table (columns in first-seen order), also written as ``fig_dir/<key>.csv``."""
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    table_rows = [[r.get(c) for c in cols] for r in rows]
    s = Section(key, title, [intro], notes=list(notes))
    if cols:
        data = write_csv(fig_dir / f"{key}.csv", cols, table_rows)
        s.tables.append(Table(cols, table_rows, title, data))
    return s
