"""Prediction: the calibrated model driven by each event's measured input (``shm-ros predict``).

The building paper's Table 3 (NRMS of floor accelerations and of the top story's drift ratio, per
event, updated against nominal model), per event its scores over the measured channels (the
calibration events, whose records the model error was learnt from, told apart from the events
predicted out of sample) and its warnings, the scores per channel, and predicted-vs-measured traces
with their 95 % bands, the strong-motion part shaded.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.report.document import Figure, Section, Table
from shm_ros.report.inputs import ReportInputs
from shm_ros.report.sections._common import figure_json, plain, pyplot

MAX_EVENT_FIGURES = 4


class PredictionSection:
    key = "prediction"
    title = "Prediction"
    order = 50

    def build(self, inputs: ReportInputs, fig_dir: Path) -> Section | None:
        p = inputs.prediction
        if p is None:
            return None
        d = p.payload
        sm = d.get("summary", {})
        intro = (f"{sm.get('n_events', len(d.get('events', [])))} event(s) predicted with the "
                 f"{d.get('model', 'calibrated')} model from their measured input.")
        if sm.get("nrms_pct_median") is not None:
            intro += (f" Median NRMS {sm['nrms_pct_median']:.1f} % (nominal model "
                      f"{_fmt(sm.get('nrms_pct_nominal_median'))} %); 95 % band coverage, strong motion "
                      f"{_pct(sm.get('coverage_95_strong_median'))}; peaks inside their interval "
                      f"{_pct(sm.get('peaks_inside_fraction'))}.")
        events = d.get("events", [])
        later = [e for e in events if not _calibrating(e)]
        if len(later) < len(events) and later:
            ms = [_measured(e) for e in later]
            outside = ", ".join(e["window_id"] for e in later if (e.get("risk") or {}).get("outside_calibration"))
            intro += (f" {len(events) - len(later)} of them are calibration events (the model error learnt from "
                      f"them); the {len(later)} later one(s), predicted out of sample: median NRMS "
                      f"{_fmt(_median([c.get('nrms_pct') for m in ms for c in m]))} %, strong-motion coverage of "
                      f"the 95 % band {_fmt3(_median([_median([c.get('coverage_95_strong') for c in m]) for m in ms]))}"
                      f" (median over events){'; outside what the calibration saw: ' + outside if outside else ''}.")
        s = Section(self.key, self.title, [intro], notes=list(p.notes))
        if d.get("table3"):
            s.tables.append(_table3(d["table3"]))
        if events:
            s.tables.append(_events(events))
        s.tables.append(_channels(d.get("events", [])))
        for ev in (p.series.get("events") or [])[:MAX_EVENT_FIGURES]:
            s.figures.append(_event_figure(ev, fig_dir))
        return s


def _fmt(v: Any) -> str:
    return "–" if v is None else f"{float(v):.1f}"


def _pct(v: Any) -> str:
    return "–" if v is None else f"{100 * float(v):.0f} %"


def _fmt3(v: Any) -> str:
    return "–" if v is None else f"{float(v):.3f}"


def _median(values: list[Any]) -> float | None:
    v = [float(x) for x in values if x is not None and np.isfinite(float(x))]
    return float(np.median(v)) if v else None


def _calibrating(ev: dict[str, Any]) -> bool:
    """Whether the event is one the model error was learnt from (one of its folds)."""
    folds = (ev.get("model_error") or {}).get("folds") or []
    return any(f.get("window_id") == ev.get("window_id") for f in folds)


def _measured(ev: dict[str, Any]) -> list[dict[str, Any]]:
    return [c for c in ev.get("channels", []) if c.get("measured")]


def _events(events: list[dict[str, Any]]) -> Table:
    rows = []
    for ev in events:
        m = _measured(ev)
        role = ("calibration" if _calibrating(ev) else "predicted") if ev.get("model_error") else "-"
        rows.append([ev.get("window_id"), role, ev.get("input_pga_m_s2"), _median([c.get("nrms_pct") for c in m]),
                     _median([c.get("nrms_pct_nominal") for c in m]), _median([c.get("coverage_95_strong") for c in m]),
                     sum(bool(c.get("peak_inside")) for c in m), len(m),
                     "; ".join((ev.get("risk") or {}).get("warnings") or []) or "none"])
    return Table(["event", "role", "input PGA m/s²", "NRMS %", "nominal NRMS %", "strong-motion coverage",
                  "peaks inside", "of", "warnings"], rows,
                 "Per event, medians over the measured channels: calibration events (the model error learnt from "
                 "their records, leave one out) and events predicted out of sample; the warnings include an input "
                 "PGA above the calibration events'")


def _table3(rows: list[dict[str, Any]]) -> Table:
    cols = ["window_id", "accel_floor4", "accel_floor4_nominal", "accel_floor8", "accel_floor8_nominal",
            "drift_top", "drift_top_nominal"]
    return Table(["event", "floor 4 NRMS %", "(nominal)", "floor 8 NRMS %", "(nominal)", "top drift ratio NRMS %",
                  "(nominal)"], [[r.get(c) for c in cols] for r in rows],
                 "NRMS per event, updated and nominal model (the building paper's Table 3)")


def _channels(events: list[dict[str, Any]]) -> Table:
    rows = []
    for ev in events:
        for c in ev.get("channels", []):
            rows.append([ev.get("window_id"), c.get("name"), c.get("quantity"), c.get("measured"),
                         c.get("nrms_pct"), c.get("nrms_pct_nominal"), c.get("coverage_95"), c.get("peak"),
                         (c.get("peak_ci95") or [None, None])[0], (c.get("peak_ci95") or [None, None])[1]])
    return Table(["event", "location", "quantity", "measured", "NRMS %", "nominal NRMS %", "band coverage",
                  "peak", "peak 2.5 %", "peak 97.5 %"], rows,
                 "Every predicted location: scores where measured, peaks and intervals everywhere")


def _event_figure(ev: dict[str, Any], fig_dir: Path) -> Figure:
    plt = pyplot()
    chans = {k: v for k, v in ev["channels"].items() if v.get("measured")}
    chans.update({k: v for k, v in ev["channels"].items() if not v.get("measured")
                  and v.get("quantity") == "drift_ratio"} if len(chans) < 6 else {})
    n = max(1, len(chans))
    fig, axes = plt.subplots(n, 1, figsize=(9, 1.8 * n + 0.4), sharex=True, squeeze=False)
    fs = float(ev["fs"])
    for ax, (name, c) in zip(axes[:, 0], chans.items(), strict=False):
        mean = np.asarray(c["mean"], float)
        t = np.arange(mean.size) / fs
        ax.fill_between(t, np.asarray(c["lower"], float), np.asarray(c["upper"], float), color="tab:blue",
                        alpha=0.25, lw=0, label="95 % band")
        if c.get("values") is not None:
            ax.plot(t, np.asarray(c["values"], float), color="k", lw=0.6, label="measured")
        ax.plot(t, mean, color="tab:blue", lw=0.8, label="updated model")
        ax.plot(t, np.asarray(c["nominal"], float), color="tab:red", lw=0.6, alpha=0.7, label="nominal model")
        a, b = ev.get("strong_s", [0, 0])
        ax.axvspan(a, b, color="0.92", zorder=-1)
        unit = {"acceleration": "m/s²", "drift": "m", "drift_ratio": "-"}.get(c.get("quantity"), "")
        ax.set_ylabel(f"{name}\n{unit}" + ("" if c.get("measured") else "\n(not measured)"), fontsize=8)
    axes[0, 0].legend(fontsize=7, ncol=4, loc="upper right")
    axes[-1, 0].set_xlabel("time from window start, s (grey: strong motion)")
    fig.suptitle(f"{ev['window_id']}: predicted vs measured", fontsize=9)
    fig.tight_layout()
    name = "prediction_" + "".join(ch if ch.isalnum() else "_" for ch in str(ev["window_id"]))
    return figure_json(fig, fig_dir, name, f"Event {ev['window_id']}: measured and predicted responses with the "
                       "95 % predictive band (grey: strong motion)", plain(ev))


BUILDER = PredictionSection()
