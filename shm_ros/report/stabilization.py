"""Stabilization diagram plot: poles per model order, by how far they got through the filters,
the picked modes, and the mean spectrum of the outputs behind them."""

from __future__ import annotations

from pathlib import Path
from typing import TypedDict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from shm_ros.core.stabilization import Diagram  # noqa: E402
from shm_ros.report.figures import save_figure  # noqa: E402

__all__ = ["plot_stabilization"]


class _ScatterStyle(TypedDict, total=False):
    """Keyword arguments of ``Axes.scatter`` for one group of poles."""

    marker: str
    s: float
    c: str
    facecolors: str
    edgecolors: str


def plot_stabilization(diagram: Diagram, path: str | Path, title: str = "",
                       freq_max_hz: float | None = None) -> Path:
    """Write the diagram of one window to ``path`` (PNG/SVG/PDF by suffix); returns the path."""
    p, fl = diagram.poles, diagram.flags
    fig, ax = plt.subplots(figsize=(9, 5.5), dpi=110)
    groups: list[tuple[str, np.ndarray, _ScatterStyle]] = [
        ("all poles", np.ones(len(p), bool), _ScatterStyle(marker=".", s=6, c="0.75")),
        ("stable in frequency", fl.stable_freq & ~fl.stable, _ScatterStyle(marker="x", s=14, c="tab:orange")),
    ]
    rep = diagram.report
    if rep is None:  # a diagram made without a filter report: the pole-by-pole view
        groups += [("stable (f, damping, MAC)", fl.stable & ~fl.candidates(True),
                    _ScatterStyle(marker="o", s=14, facecolors="none", edgecolors="tab:blue")),
                   ("stable + two-A + MPC + physical", fl.candidates(True),
                    _ScatterStyle(marker="o", s=16, c="tab:green"))]
    else:  # every stable pole under the reason it was removed (legend: how many), or picked
        colours = {"physical": "tab:purple", "two-A": "tab:blue", "MPC": "tab:cyan",
                   "too few orders": "tab:olive", "same order": "tab:brown", "duplicate": "tab:pink"}
        for reason, colour in colours.items():
            groups.append((rep.legend(reason), rep.removed_by == reason,
                           _ScatterStyle(marker="o", s=14, facecolors="none", edgecolors=colour)))
        groups.append(("in a picked mode (stable column)", rep.removed_by == "picked",
                       _ScatterStyle(marker="o", s=16, c="tab:green")))
    for label, mask, style in groups:
        if np.any(mask):
            ax.scatter(p.frequency_hz[mask], p.order[mask], label=label, **style)
    for m in diagram.picked:
        ax.axvline(m.frequency_hz, color="tab:red", lw=0.8, alpha=0.7)
        ax.text(m.frequency_hz, ax.get_ylim()[1] if len(p) else 1, f"{m.frequency_hz:.3g}",
                rotation=90, va="top", ha="right", fontsize=7, color="tab:red")
    if diagram.spectrum_hz is not None and diagram.spectrum is not None and len(p):
        ax2 = ax.twinx()
        spec = np.asarray(diagram.spectrum)
        ax2.semilogy(diagram.spectrum_hz, np.maximum(spec, spec.max() * 1e-12), color="0.4", lw=0.8)
        ax2.set_ylabel("mean PSD of the outputs")
    fmax = freq_max_hz or (float(np.max(p.frequency_hz)) if len(p) else 1.0)
    ax.set_xlim(0, fmax)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("model order")
    ax.set_title(title or "stabilization diagram")
    ax.legend(loc="lower right", fontsize=7, framealpha=0.9)
    return save_figure(fig, path)
