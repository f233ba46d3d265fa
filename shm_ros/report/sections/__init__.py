"""One module per stage; each exposes ``BUILDER`` (a :class:`SectionBuilder`).

A new stage's section is a new module in this package: it is found by :func:`builders` (modules
whose name starts with ``_`` are helpers) and placed by its ``order``. ``build`` returns ``None``
when the stage's input is absent, so the report grows with the stages that have run.
"""

from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path
from typing import Protocol

from shm_ros.report.document import Section
from shm_ros.report.inputs import ReportInputs

__all__ = ["SectionBuilder", "builders"]


class SectionBuilder(Protocol):
    key: str  # the HTML heading id is ``section-<key>``
    title: str
    order: int  # position in the report (data flows top to bottom)

    def build(self, inputs: ReportInputs, fig_dir: Path) -> Section | None:
        """The section, with its figures (PNG + data file) written into ``fig_dir``; None when
        the stage's input is absent."""
        ...


def builders() -> list[SectionBuilder]:
    """Every section builder of this package, in report order."""
    found: list[SectionBuilder] = []
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        builder = getattr(module, "BUILDER", None)
        if builder is not None:
            found.append(builder)
    keys = [b.key for b in found]
    dup = sorted({k for k in keys if keys.count(k) > 1})
    if dup:
        raise RuntimeError(f"report sections: duplicated key(s) {dup}")
    return sorted(found, key=lambda b: (b.order, b.key))
