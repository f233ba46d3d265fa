"""Data health (ingest): the windows, their channels' coverage and status, and the diagnostics."""

from __future__ import annotations

from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.report.document import Section, Table
from shm_ros.report.inputs import IngestInputs, ReportInputs, WindowHealth
from shm_ros.report.sections._common import figure_csv, iso_ns, pyplot, write_csv

#: windows listed in the HTML/Markdown table; the CSV next to it has all of them
MAX_ROWS = 40
_LEVEL_ORDER = {"error": 0, "stale": 1, "warning": 2, "info": 3}
_STATUS_MARK = {"dead": "D", "clipped": "C", "noisy": "N", "dropped": "X"}


def _span(values: list[float], unit: str, fmt: str = ".4g") -> str:
    lo, hi = min(values), max(values)
    return f"{lo:{fmt}} {unit}" if lo == hi else f"{lo:{fmt}} to {hi:{fmt}} {unit}"


class DataHealthSection:
    key = "ingest"
    title = "Data health (ingest)"
    order = 10

    def build(self, inputs: ReportInputs, fig_dir: Path) -> Section | None:
        ing = inputs.ingest
        if ing is None:
            return None
        s = Section(self.key, self.title)
        ws = sorted(ing.windows, key=lambda w: w.start_ns)
        s.paragraphs.append(self._summary(ing, ws))
        if ws:
            s.tables.append(self._windows_table(ws, fig_dir))
            s.figures.append(self._coverage_figure(ws, fig_dir))
        s.tables.append(self._diagnostics_table(ing, fig_dir))
        return s

    @staticmethod
    def _summary(ing: IngestInputs, ws: list[WindowHealth]) -> str:
        if not ws:
            return "No window was made from the recording; the diagnostics below say why."
        channels = sorted({c for w in ws for c in w.channels})
        cov = np.concatenate([np.asarray(w.coverage, float) for w in ws]) if ws else np.zeros(0)
        bad = sum(1 for w in ws if any(st != "ok" for st in w.status))
        quakes = sum(1 for w in ws if w.is_event and w.event_kind == "earthquake")
        loud = sum(1 for w in ws if w.is_event) - quakes
        dropped = sum(int(d.get("n_samples") or 0) for d in ing.dropped)
        text = (f"{len(ws)} windows from {iso_ns(ws[0].start_ns)} to {iso_ns(ws[-1].end_ns)}; "
                f"length {_span([(w.end_ns - w.start_ns) / 1e9 for w in ws], 's')}, "
                f"sample rate {_span([w.sample_rate_hz for w in ws], 'Hz')}; {len(channels)} channels "
                f"({', '.join(channels)}). Mean channel coverage {100 * float(np.mean(cov)):.2f} % "
                f"(lowest {100 * float(np.min(cov)):.2f} %); {bad} windows with a channel not ok; "
                f"{quakes} earthquake windows (the ground/input sensor shook) and {loud} high-amplitude windows "
                f"(traffic, wind or works).")
        if ing.dropped:
            text += f" {len(ing.dropped)} stretches ({dropped} samples) went into no window."
        return text

    @staticmethod
    def _windows_table(ws: list[WindowHealth], fig_dir: Path) -> Table:
        cols = ["window", "start (UTC)", "length (s)", "rate (Hz)", "channels", "min coverage (%)",
                "channels not ok", "temperature (°C)", "event", "PGA (m/s²)"]
        rows: list[list[Any]] = []
        for w in ws:
            not_ok = ", ".join(f"{c}: {st}" for c, st in zip(w.channels, w.status, strict=True) if st != "ok")
            rows.append([w.window_id, iso_ns(w.start_ns), (w.end_ns - w.start_ns) / 1e9, w.sample_rate_hz,
                         len(w.channels), 100 * min(w.coverage, default=0.0), not_ok or "–",
                         w.temperature_c, _event_name(w), w.pga_m_s2])
        data = write_csv(fig_dir / "windows.csv", cols, rows)
        if all(r[0][:19] == r[1][:19] for r in rows):  # ids are the start times: show them once
            cols, rows = cols[1:], [r[1:] for r in rows]
        shown = rows if len(rows) <= MAX_ROWS else rows[:MAX_ROWS // 2] + rows[-MAX_ROWS // 2:]
        cap = "Windows" if len(rows) <= MAX_ROWS else f"Windows (first and last {MAX_ROWS // 2} of {len(rows)})"
        return Table(cols, shown, cap, data)

    @staticmethod
    def _diagnostics_table(ing: IngestInputs, fig_dir: Path) -> Table:
        counts: Counter[tuple[str, str, str]] = Counter()
        example: dict[tuple[str, str, str], str] = {}
        for d in ing.diagnostics:
            k = (d.level, d.code, d.source)
            counts[k] += d.count
            example.setdefault(k, d.message)
        keys = sorted(counts, key=lambda k: (_LEVEL_ORDER.get(k[0], 9), k[1], k[2]))
        cols = ["level", "code", "source", "count", "first message"]
        rows = [[*k, counts[k], example[k][:160]] for k in keys]
        data = write_csv(fig_dir / "diagnostics.csv", cols, rows)
        by_level = Counter({lvl: 0 for lvl in ("error", "warning", "info")})
        for d in ing.diagnostics:
            by_level[d.level] += 1
        cap = ("Diagnostics by level, code and source (" + ", ".join(f"{lvl} {n}" for lvl, n in by_level.items())
               + " reported; count: occurrences, e.g. samples)")
        return Table(cols, rows or [["–", "none", "", 0, ""]], cap, data)

    @staticmethod
    def _coverage_figure(ws: list[WindowHealth], fig_dir: Path):
        plt = pyplot()
        channels = list(dict.fromkeys(c for w in ws for c in w.channels))
        cov = np.full((len(channels), len(ws)), np.nan)
        status: dict[tuple[int, int], str] = defaultdict(lambda: "absent")
        for j, w in enumerate(ws):
            for c, st, v in zip(w.channels, w.status, w.coverage, strict=True):
                i = channels.index(c)
                cov[i, j], status[i, j] = 100 * v, st
        fig, ax = plt.subplots(figsize=(min(14, 4 + 0.25 * len(ws)), 1.2 + 0.35 * len(channels)))
        im = ax.imshow(cov, aspect="auto", cmap="RdYlGn", vmin=max(0, np.nanmin(cov) - 1) if np.isfinite(cov).any()
                       else 0, vmax=100, interpolation="nearest")
        for (i, j), st in status.items():
            if st in _STATUS_MARK:
                ax.text(j, i, _STATUS_MARK[st], ha="center", va="center", fontsize=8, color="k", weight="bold")
        ax.set_yticks(range(len(channels)), channels)
        step = max(1, len(ws) // 12)
        ax.set_xticks(range(0, len(ws), step), [iso_ns(w.start_ns)[5:16].replace("T", " ") for w in ws[::step]],
                      rotation=30, ha="right", fontsize=8)
        ax.set_xlabel("window start (UTC)")
        ax.set_title("channel coverage per window (%); D dead, C clipped, N noisy, X dropped")
        fig.colorbar(im, ax=ax, label="coverage (%)", fraction=0.04)
        rows = [[w.window_id, iso_ns(w.start_ns), c, cov[i, j] / 100 if np.isfinite(cov[i, j]) else None, status[i, j]]
                for j, w in enumerate(ws) for i, c in enumerate(channels)]
        return figure_csv(fig, fig_dir, "ingest_coverage", "Coverage of every channel in every window; a letter "
                          "marks a channel whose status is not ok.",
                          ["window_id", "start", "channel", "coverage", "status"], rows)


BUILDER = DataHealthSection()


def _event_name(w: WindowHealth) -> str:
    """The window's event column: earthquake, high-amplitude or –."""
    if not w.is_event:
        return "–"
    return "earthquake" if w.event_kind == "earthquake" else "high-amplitude"
