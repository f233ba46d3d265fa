"""HTML summary of identified modes, against the simulator's truth when there is one."""

from __future__ import annotations

import html
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.core.modal import mac
from shm_ros.core.types import ModalEstimate


@dataclass
class TruthMatch:
    """Identified vs true modes of one window: per true mode, the closest identified one."""

    window_id: str
    true_hz: list[float]
    found_hz: list[float | None]
    error_pct: list[float | None]
    mac: list[float | None]


def match_to_truth(estimates: list[ModalEstimate], truth: dict[str, Any], n_modes: int = 4,
                   tolerance: float = 0.05) -> list[TruthMatch]:
    """Pair each window's estimate with the truth window that starts at the same time."""
    by_start = {int(w["start_ns"]): w for w in truth.get("windows", [])}
    out = []
    for e in sorted(estimates, key=lambda e: e.start_ns):
        tw = by_start.get(e.start_ns)
        if tw is None:
            continue
        # the in-plane modes (the simulator also lists out-of-plane ones, marked in mode_families)
        fams, plane = tw.get("mode_families") or [], (truth.get("truth_model") or {}).get("in_plane_family")
        idx = ([k for k, f in enumerate(fams) if f == plane] if fams and plane
               else list(range(len(tw["frequencies_hz"]))))
        true_f = [tw["frequencies_hz"][k] for k in idx[:n_modes]]
        shapes = tw.get("mode_shapes", {})
        found: list[float | None] = []
        err: list[float | None] = []
        macs: list[float | None] = []
        for k, f in enumerate(true_f):
            cands = [m for m in e.modes if abs(m.frequency_hz - f) <= tolerance * f]
            if not cands:
                found.append(None)
                err.append(None)
                macs.append(None)
                continue
            best = min(cands, key=lambda m: abs(m.frequency_hz - f))
            found.append(best.frequency_hz)
            err.append(100.0 * (best.frequency_hz - f) / f)
            true_shape = _true_shape(shapes, idx[k], e.sensor_ids)
            macs.append(None if true_shape is None else float(mac(np.asarray(best.mode_shape), true_shape)))
        out.append(TruthMatch(e.window_id, true_f, found, err, macs))
    return out


def _true_shape(shapes: Any, k: int, sensor_ids: list[str]) -> np.ndarray | None:
    try:
        if isinstance(shapes, dict):
            return np.array([shapes[s][k] for s in sensor_ids], dtype=float)
        return np.asarray(shapes[k], dtype=float)
    except (KeyError, IndexError, TypeError):
        return None


def plot_frequencies(estimates: list[ModalEstimate], matches: list[TruthMatch], path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    ordered = sorted(estimates, key=lambda e: e.start_ns)
    for i, e in enumerate(ordered):
        ax.plot([i] * len(e.modes), [m.frequency_hz for m in e.modes], "o", color="C0", ms=5,
                label="identified" if i == 0 else None)
    for i, m in enumerate(matches):
        ax.plot([i] * len(m.true_hz), m.true_hz, "_", color="C3", ms=16, mew=2,
                label="truth" if i == 0 else None)
    ax.set_xlabel("window")
    ax.set_ylabel("frequency [Hz]")
    ax.set_title("Identified modes per window")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_report(path: str | Path, estimates: list[ModalEstimate], truth: dict | None,
                 facts: dict[str, Any], diagnostics: list[str]) -> Path:
    path = Path(path)
    matches = match_to_truth(estimates, truth) if truth else []
    plot = plot_frequencies(estimates, matches, path.with_name("frequencies.png"))
    rows = []
    for e in sorted(estimates, key=lambda e: e.start_ns):
        freqs = ", ".join(f"{m.frequency_hz:.3f} ({100 * m.damping_ratio:.1f} %)" for m in e.modes)
        temp = "" if e.temperature_c is None else f"{e.temperature_c:.1f}"
        rows.append(f"<tr><td>{html.escape(e.window_id)}</td><td>{temp}</td><td>{freqs}</td></tr>")
    truth_rows = []
    for m in matches:
        cells = "".join(
            f"<td>{t:.3f}</td><td>{'-' if f is None else f'{f:.3f}'}</td>"
            f"<td>{'-' if e is None else f'{e:+.2f}'}</td><td>{'-' if c is None else f'{c:.3f}'}</td>"
            for t, f, e, c in zip(m.true_hz, m.found_hz, m.error_pct, m.mac, strict=True))
        truth_rows.append(f"<tr><td>{html.escape(m.window_id)}</td>{cells}</tr>")
    n_true = max((len(m.true_hz) for m in matches), default=0)
    head = "".join(f"<th>mode {k + 1} truth [Hz]</th><th>found</th><th>error [%]</th><th>MAC</th>"
                   for k in range(n_true))
    facts_html = "".join(f"<tr><th>{html.escape(str(k))}</th><td>{html.escape(str(v))}</td></tr>"
                         for k, v in facts.items())
    diag_html = "".join(f"<li>{html.escape(d)}</li>" for d in diagnostics[:200]) or "<li>none</li>"
    path.write_text(f"""<!doctype html>
<html><head><meta charset="utf-8"><title>shm_ros report</title>
<style>body{{font-family:sans-serif;margin:2em}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:3px 8px;text-align:right}}</style></head><body>
<h1>shm_ros: identified modes</h1>
<table>{facts_html}</table>
<h2>Modes per window (frequency, damping)</h2>
<table><tr><th>window</th><th>T [&deg;C]</th><th>modes</th></tr>{''.join(rows)}</table>
<h2>Against the simulator's truth</h2>
<table><tr><th>window</th>{head}</tr>{''.join(truth_rows)}</table>
<p><img src="{plot.name}" alt="frequencies per window"></p>
<h2>Diagnostics (warnings and errors)</h2><ul>{diag_html}</ul>
</body></html>
""")
    return path
