"""What the report is built from: one optional field per stage (a section appears when it is set).

The fields are the project's own result types (``Window``/``ModalEstimate`` of
``shm_ros.core.types``, ``TrackingResult``, ``Posterior``) plus small records for what has no type
of its own yet (diagnostics, per-window health as ``windows.json`` stores it) and placeholders for
the stages that do not exist yet (prediction, explanation).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from shm_ros.core.types import ModalEstimate, SampleFlag, Window

if TYPE_CHECKING:  # heavy modules; only their types are needed here
    from shm_ros.core.bayes.update import Posterior
    from shm_ros.core.stabilization import Diagram
    from shm_ros.core.tracking import TrackingResult

__all__ = ["DiagnosticRow", "ExplainInputs", "IdentifyInputs", "IngestInputs", "PredictionInputs",
           "ReportInputs", "WindowHealth"]

#: diagnostic_msgs levels (0 OK, 1 WARN, 2 ERROR, 3 STALE) by the names ``windows.json`` uses
LEVELS = {0: "info", 1: "warning", 2: "error", 3: "stale"}


@dataclass
class DiagnosticRow:
    """One diagnostic, from a ``Diagnostic`` of the ingest core or a record of ``windows.json``."""

    level: str
    code: str
    source: str
    message: str
    count: int = 1

    @classmethod
    def from_any(cls, d: Any) -> DiagnosticRow:
        get = d.get if isinstance(d, Mapping) else (lambda k, default=None: getattr(d, k, default))
        level = get("level", "info")
        level = LEVELS.get(int(level), str(level)) if isinstance(level, (int, np.integer)) else str(level)
        return cls(level, str(get("code", "")), str(get("source", "")), str(get("message", "")),
                   int(get("count", 1) or 1))


@dataclass
class WindowHealth:
    """What the data-health section needs of one window (no samples)."""

    window_id: str
    start_ns: int
    end_ns: int
    sample_rate_hz: float
    n_samples: int
    channels: list[str]
    status: list[str]  # per channel: ok | dead | clipped | noisy | dropped
    coverage: list[float]  # per channel: fraction of samples present and finite
    temperature_c: float | None = None
    is_event: bool = False
    pga_m_s2: float = 0.0
    flagged: dict[str, dict[str, int]] = field(default_factory=dict)  # channel -> flag name -> count
    event_kind: str = ""  # earthquake | high_amplitude | none ("" = not named: an event counts as high-amplitude)

    @classmethod
    def from_window(cls, w: Window) -> WindowHealth:
        n = max(w.n_samples, 1)
        finite = np.isfinite(w.samples)
        if w.flags is not None:
            finite &= (w.flags & int(SampleFlag.MISSING)) == 0
        flagged: dict[str, dict[str, int]] = {}
        if w.flags is not None:
            for c, name in enumerate(w.channel_names):
                counts = {str(f.name).lower(): int(((w.flags[:, c] & f) != 0).sum()) for f in SampleFlag if f}
                flagged[name] = {k: v for k, v in counts.items() if v}
        return cls(w.window_id, int(w.start_ns), int(w.end_ns), float(w.sample_rate_hz), w.n_samples,
                   list(w.channel_names), list(w.channel_status or ["ok"] * len(w.channel_names)),
                   [float(x) for x in finite.sum(axis=0) / n], w.temperature_c, bool(w.is_event),
                   float(w.pga_m_s2), flagged, w.event_kind)

    @classmethod
    def from_record(cls, r: Mapping[str, Any]) -> WindowHealth:
        """A record of ``windows.json`` (``shm-ros ingest``): coverage from its flagged counts."""
        channels = [str(c) for c in r.get("channel_names", [])]
        n = int(r.get("n_samples", 0))
        flagged = {str(k): {str(f): int(c) for f, c in v.items()} for k, v in (r.get("flagged_samples") or {}).items()}
        coverage = []
        for c in channels:
            lost = flagged.get(c, {}).get("missing", 0) + flagged.get(c, {}).get("nan", 0)
            coverage.append(1.0 - min(lost, n) / n if n else 0.0)
        status = [str(s) for s in r.get("channel_status") or []] or ["ok"] * len(channels)
        t = r.get("temperature_c")
        return cls(str(r.get("window_id", "")), int(r["start_ns"]), int(r["end_ns"]),
                   float(r.get("sample_rate_hz", math.nan)), n, channels, status, coverage,
                   None if t is None else float(t), bool(r.get("is_event", False)),
                   float(r.get("pga_m_s2", 0.0) or 0.0), flagged, str(r.get("event_kind") or ""))


@dataclass
class IngestInputs:
    windows: list[WindowHealth]
    diagnostics: list[DiagnosticRow] = field(default_factory=list)
    dropped: list[dict[str, Any]] = field(default_factory=list)  # start_ns, end_ns, n_samples, reason

    @classmethod
    def from_windows(cls, windows: Iterable[Window], diagnostics: Iterable[Any] = (),
                     dropped: Iterable[Any] = ()) -> IngestInputs:
        """From the ingest core's results (``IngestResult.windows/.diagnostics/.dropped``)."""
        drops = [d if isinstance(d, Mapping) else
                 {k: getattr(d, k, None) for k in ("start_ns", "end_ns", "n_samples", "reason")}
                 for d in dropped]
        return cls([WindowHealth.from_window(w) for w in windows],
                   [DiagnosticRow.from_any(d) for d in diagnostics], [dict(d) for d in drops])


@dataclass
class IdentifyInputs:
    estimates: list[ModalEstimate]
    diagrams: dict[str, Diagram] = field(default_factory=dict)  # window_id -> stabilization diagram
    method: str = ""


@dataclass
class PredictionInputs:
    """What ``shm-ros predict`` wrote: ``payload`` (prediction.json, docs/interfaces.md §7) and
    ``series`` (prediction_series.json: per event and location the traces and bands), plus remarks."""

    payload: dict[str, Any]
    series: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    @classmethod
    def from_files(cls, path: str | Path) -> PredictionInputs:
        from shm_ros.io.prediction_files import read_prediction

        payload, series = read_prediction(path)
        return cls(payload, series, [str(e) for e in payload.get("errors", [])])


@dataclass
class ExplainInputs:
    """What ``shm-ros explain`` wrote: ``verdict`` (verdict.json, docs/interfaces.md §5) and ``series``
    (explain_series.json: per window times, covariates, residuals before / after, training mask,
    fitted forms), plus remarks."""

    verdict: dict[str, Any]
    series: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    @classmethod
    def from_files(cls, path: str | Path) -> ExplainInputs:
        from shm_ros.io.verdict_files import read_verdict

        verdict, series = read_verdict(path)
        return cls(verdict, series, list(verdict.get("notes", [])))


@dataclass
class ReportInputs:
    title: str = "shm_ros report"
    facts: dict[str, Any] = field(default_factory=dict)
    ingest: IngestInputs | None = None
    identify: IdentifyInputs | None = None
    truth: dict[str, Any] | None = None  # truth.json of the simulator
    tracking: TrackingResult | None = None
    posterior: Posterior | None = None
    prediction: PredictionInputs | None = None
    explain: ExplainInputs | None = None
    # a roving campaign's setups and global modes (modes.json of a structure with roving sensors,
    # docs/interfaces.md section 8)
    roving: dict[str, Any] | None = None
    # the papers' tables that apply: {"table1": study.json's content (``shm-ros update --study``)};
    # Table 3 comes with ``prediction``
    papers: dict[str, Any] | None = None
