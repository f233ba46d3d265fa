"""``build_report(inputs, out_dir)``: every section whose stage has run, written as HTML and Markdown."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from shm_ros import __version__
from shm_ros.report.document import Figure, Report, Section
from shm_ros.report.inputs import ReportInputs
from shm_ros.report.sections import builders

__all__ = ["ReportFiles", "build_report"]


@dataclass
class ReportFiles:
    html: Path
    markdown: Path
    figures: list[Figure]
    sections: list[str]  # keys, in report order


def build_report(inputs: ReportInputs, out_dir: str | Path) -> ReportFiles:
    """Build the sections of the stages present in ``inputs`` into ``out_dir`` (figures and their
    data files in ``out_dir/figures``) and write ``report.html`` and ``report.md``."""
    out = Path(out_dir)
    fig_dir = out / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    sections: list[Section] = []
    for b in builders():
        s = b.build(inputs, fig_dir)
        if s is not None:
            sections.append(s)
    facts = {"generated": datetime.now(timezone.utc).isoformat(timespec="seconds").replace("+00:00", "Z"),
             "shm_ros": __version__, **inputs.facts,
             "sections": ", ".join(s.title for s in sections) or "none (no stage output was given)"}
    from shm_ros.report.summary import summary_sentences

    html, md = Report(inputs.title, facts, sections, summary_sentences(inputs)).write(out)
    return ReportFiles(html, md, [f for s in sections for f in s.figures], [s.key for s in sections])
