"""Prediction: shown when the prediction stage's results are given (its inputs are a placeholder,
:class:`~shm_ros.report.inputs.PredictionInputs`, until that stage exists)."""

from __future__ import annotations

from pathlib import Path

from shm_ros.report.document import Section
from shm_ros.report.inputs import ReportInputs
from shm_ros.report.sections._rows import rows_section


class PredictionSection:
    key = "prediction"
    title = "Prediction"
    order = 50

    def build(self, inputs: ReportInputs, fig_dir: Path) -> Section | None:
        p = inputs.prediction
        if p is None:
            return None
        return rows_section(self.key, self.title, f"{len(p.rows)} predicted quantities of the calibrated model.",
                            p.rows, p.notes, fig_dir)


BUILDER = PredictionSection()
