"""The report as a document: sections of paragraphs, tables and figures, written twice.

``report.html`` is self-contained (figures embedded as base64 ``data:`` URIs, inline CSS, no
script, no external resource), so it opens offline and can be mailed as one file. ``report.md``
links the PNG files in ``figures/`` next to it. Every :class:`Figure` names the data file (CSV or
JSON) that holds its numbers; both outputs link it.
"""

from __future__ import annotations

import base64
import html
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Figure", "Report", "Section", "Table", "format_cell", "section_anchor"]


@dataclass
class Table:
    """Rows of already chosen values; numbers are formatted by :func:`format_cell`."""

    columns: list[str]
    rows: list[list[Any]]
    caption: str = ""
    data_path: Path | None = None  # the full table when ``rows`` is a shortened view of it


@dataclass
class Figure:
    png: Path
    data: Path  # CSV or JSON with the figure's numbers, next to the PNG
    caption: str


@dataclass
class Section:
    key: str  # stable identifier: the HTML heading id is ``section-<key>``
    title: str
    paragraphs: list[str] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
    figures: list[Figure] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)  # warnings and remarks, shown as a list


def section_anchor(key: str) -> str:
    return f"section-{key}"


def format_cell(v: Any) -> str:
    """Floats to 4 significant digits; None and non-finite numbers as an en dash."""
    if v is None:
        return "–"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        x = float(v)
        return f"{x:.4g}" if math.isfinite(x) else "–"
    return str(v)


_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",sans-serif;margin:0;color:#222;background:#fafafa}
main{max-width:1200px;margin:0 auto;padding:1em 2em 4em;background:#fff}
h1{border-bottom:2px solid #345;padding-bottom:.3em}
h2{margin-top:2em;border-bottom:1px solid #ccc;padding-bottom:.2em;color:#234}
nav ol{columns:2}
table{border-collapse:collapse;margin:.6em 0 1.2em;font-size:.9em}
caption{caption-side:top;text-align:left;font-weight:600;padding:.3em 0}
td,th{border:1px solid #ccc;padding:3px 8px;text-align:right;vertical-align:top}
th{background:#eef2f6}
td.t,th.t{text-align:left}
table.facts th{text-align:left}
figure{margin:1em 0 2em}
figure img{max-width:100%;height:auto;border:1px solid #ddd}
figcaption{font-size:.9em;color:#444;margin-top:.3em}
ul.notes li{color:#7a4b00}
.data{font-size:.85em}
"""


class Report:
    """A title, a table of facts, and the sections of the stages that ran."""

    def __init__(self, title: str, facts: dict[str, Any] | None = None,
                 sections: list[Section] | None = None, summary: list[str] | None = None) -> None:
        self.title = title
        self.facts = dict(facts or {})
        self.sections = list(sections or [])
        self.summary = list(summary or [])  # plain sentences shown first (report/summary.py)

    def write(self, out_dir: str | Path) -> tuple[Path, Path]:
        """Write ``report.html`` and ``report.md`` into ``out_dir``; returns their paths."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        html_path, md_path = out / "report.html", out / "report.md"
        html_path.write_text(self.to_html(out), encoding="utf-8")
        md_path.write_text(self.to_markdown(out), encoding="utf-8")
        return html_path, md_path

    # -- HTML ---------------------------------------------------------------------------------

    def to_html(self, base_dir: Path) -> str:
        e = html.escape
        parts = [f"<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
                 f"<meta name=\"viewport\" content=\"width=device-width,initial-scale=1\">"
                 f"<title>{e(self.title)}</title><style>{_CSS}</style></head><body><main>",
                 f"<h1 id=\"top\">{e(self.title)}</h1>"]
        if self.summary:
            items = "".join(f"<li>{e(x)}</li>" for x in self.summary)
            parts.append("<section class=\"summary\"><h2 id=\"section-summary\">Summary</h2>"
                         f"<ul>{items}</ul></section>")
        if self.facts:
            rows = "".join(f"<tr><th>{e(str(k))}</th><td class=\"t\">{e(format_cell(v))}</td></tr>"
                           for k, v in self.facts.items())
            parts.append(f"<table class=\"facts\">{rows}</table>")
        if self.sections:
            items = "".join(f"<li><a href=\"#{section_anchor(s.key)}\">{e(s.title)}</a></li>"
                            for s in self.sections)
            parts.append(f"<nav><ol>{items}</ol></nav>")
        for s in self.sections:
            parts.append(self._section_html(s, base_dir))
        parts.append("</main></body></html>\n")
        return "\n".join(parts)

    def _section_html(self, s: Section, base_dir: Path) -> str:
        e = html.escape
        out = [f"<section><h2 id=\"{section_anchor(s.key)}\">{e(s.title)}</h2>"]
        out += [f"<p>{e(p)}</p>" for p in s.paragraphs]
        if s.notes:
            out.append("<ul class=\"notes\">" + "".join(f"<li>{e(n)}</li>" for n in s.notes) + "</ul>")
        for t in s.tables:
            out.append(_table_html(t, base_dir))
        for f in s.figures:
            data = base64.b64encode(Path(f.png).read_bytes()).decode("ascii")
            out.append(f"<figure><img src=\"data:image/png;base64,{data}\" alt=\"{e(f.caption)}\">"
                       f"<figcaption>{e(f.caption)} <span class=\"data\">(numbers: "
                       f"<code>{e(_rel(f.data, base_dir))}</code>)</span></figcaption></figure>")
        out.append("</section>")
        return "\n".join(out)

    # -- Markdown -----------------------------------------------------------------------------

    def to_markdown(self, base_dir: Path) -> str:
        lines = [f"# {_md(self.title)}", ""]
        if self.summary:
            lines += ["## Summary", "", *[f"- {_md(x)}" for x in self.summary], ""]
        if self.facts:
            lines += ["| | |", "|---|---|"]
            lines += [f"| {_md(str(k))} | {_md(format_cell(v))} |" for k, v in self.facts.items()]
            lines.append("")
        for s in self.sections:
            lines += [f"## {_md(s.title)}", ""]
            for p in s.paragraphs:
                lines += [_md_text(p), ""]
            if s.notes:
                lines += [f"- {_md(n)}" for n in s.notes] + [""]
            for t in s.tables:
                lines += _table_md(t, base_dir)
            for f in s.figures:
                png, data = _rel(f.png, base_dir), _rel(f.data, base_dir)
                lines += [f"![{_md(f.caption)}]({png})", "",
                          f"*{_md(f.caption)}* (numbers: [{Path(data).name}]({data}))", ""]
        return "\n".join(lines) + "\n"


def _rel(path: Path, base_dir: Path) -> str:
    return Path(os.path.relpath(Path(path).resolve(), Path(base_dir).resolve())).as_posix()


def _md_text(text: str) -> str:
    """Text for Markdown that stays text: no raw HTML (``<svg onload=...>``), no links or images made
    of input (``[x](javascript:...)``)."""
    return html.escape(text, quote=False).replace("[", "\\[").replace("]", "\\]")


def _md(text: str) -> str:
    """:func:`_md_text` on one line of a table or list."""
    return _md_text(text).replace("|", "\\|").replace("\n", " ")


def _is_text(v: Any) -> bool:
    return isinstance(v, str)


def _table_html(t: Table, base_dir: Path) -> str:
    e = html.escape
    cap = e(t.caption)
    if t.data_path is not None:
        cap += f" <span class=\"data\">(full table: <code>{e(_rel(t.data_path, base_dir))}</code>)</span>"
    text_col = [i == 0 or any(_is_text(r[i]) and r[i] != "–" for r in t.rows if i < len(r))
                for i in range(len(t.columns))]
    head = "".join(f"<th class=\"t\">{e(c)}</th>" if text_col[i] else f"<th>{e(c)}</th>"
                   for i, c in enumerate(t.columns))
    body = "".join("<tr>" + "".join(
        f"<td class=\"t\">{e(format_cell(v))}</td>" if i < len(text_col) and text_col[i]
        else f"<td>{e(format_cell(v))}</td>"
        for i, v in enumerate(row)) + "</tr>" for row in t.rows)
    return f"<table><caption>{cap}</caption><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _table_md(t: Table, base_dir: Path) -> list[str]:
    lines = []
    if t.caption:
        lines += [f"**{_md(t.caption)}**", ""]
    lines.append("| " + " | ".join(_md(c) for c in t.columns) + " |")
    lines.append("|" + "|".join("---" for _ in t.columns) + "|")
    lines += ["| " + " | ".join(_md(format_cell(v)) for v in row) + " |" for row in t.rows]
    lines.append("")
    if t.data_path is not None:
        rel = _rel(t.data_path, base_dir)
        lines += [f"Full table: [{Path(rel).name}]({rel})", ""]
    return lines
