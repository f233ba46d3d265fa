"""Explanation (missing physics): shown when that stage's results are given (its inputs are a
placeholder, :class:`~shm_ros.report.inputs.ExplainInputs`, until that stage exists)."""

from __future__ import annotations

from pathlib import Path

from shm_ros.report.document import Section
from shm_ros.report.inputs import ReportInputs
from shm_ros.report.sections._rows import rows_section


class ExplainSection:
    key = "explain"
    title = "Explanation (missing physics)"
    order = 60

    def build(self, inputs: ReportInputs, fig_dir: Path) -> Section | None:
        x = inputs.explain
        if x is None:
            return None
        return rows_section(self.key, self.title, f"{len(x.rows)} candidate explanations of what the "
                            "calibrated model misses.", x.rows, x.notes, fig_dir)


BUILDER = ExplainSection()
