"""Within-event figure: the input acceleration with the strong-motion interval, the followed modes'
frequencies against time, and against the response amplitude of each moving window."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from shm_ros.core.event_analysis import EventResult  # noqa: E402
from shm_ros.report.figures import save_figure  # noqa: E402

__all__ = ["plot_event"]


def plot_event(result: EventResult, path: str | Path, title: str = "") -> Path:
    """Write the three-panel figure of one event to ``path`` (format by suffix); returns the path.
    Frequencies are drawn relative to each mode's reference (pre-event) frequency so that all modes
    share one axis."""
    fig, (ax_u, ax_t, ax_a) = plt.subplots(3, 1, figsize=(9, 10), dpi=110)
    sm = result.strong_motion
    t = result.time_s
    if result.input_m_s2.size:
        ax_u.plot(result.input_time_s, result.input_m_s2, color="0.3", lw=0.6)
        ax_u.set_ylabel(f"input {result.input_channel} (m/s$^2$)")
    else:
        ax_u.plot(t, result.response_rms_m_s2, color="0.3", lw=0.8)
        ax_u.set_ylabel(f"window RMS {result.amplitude_channel} (m/s$^2$)")
    label = f"strong motion (Arias {100 * sm.arias_low:.0f}-{100 * sm.arias_high:.0f} % of the {sm.source})"
    for ax in (ax_u, ax_t):
        ax.axvspan(sm.start_s, sm.end_s, color="tab:red", alpha=0.12, label=label)
    for p in result.phases:
        if p.modes and p.name != "strong":
            ax_t.axvspan(p.start_s, p.end_s, color="tab:blue", alpha=0.06)
    for m in result.tracks:
        rel = m.frequency_hz / m.reference_frequency_hz
        line, = ax_t.plot(t, rel, ".", ms=3, label=f"mode {m.mode} ({m.reference_frequency_hz:.3g} Hz)")
        ax_a.semilogx(result.response_rms_m_s2, rel, ".", ms=3, color=line.get_color(), label=f"mode {m.mode}")
        if m.min_index is not None:
            k = m.min_index
            ax_t.plot(t[k], m.smoothed_frequency_hz[k] / m.reference_frequency_hz, "v", color=line.get_color(), ms=8)
    ax_u.set_xlabel("time from the record start (s)")
    ax_u.legend(loc="upper right", fontsize=8)
    ax_t.set_xlim(ax_u.get_xlim())
    ax_t.set_xlabel("time from the record start (s), window centres")
    ax_t.set_ylabel("frequency / reference")
    ax_t.legend(loc="lower right", fontsize=8)
    ax_a.set_xlabel(f"window RMS response {result.amplitude_channel} (m/s$^2$)")
    ax_a.set_ylabel("frequency / reference")
    ax_a.legend(loc="lower left", fontsize=8)
    for ax in (ax_t, ax_a):
        ax.grid(alpha=0.3)
    if not np.any(np.isfinite(result.response_rms_m_s2)):
        ax_a.set_xscale("linear")
    ax_u.set_title(title or f"{result.window_id}: {result.method}, {result.window_s:.1f} s windows every "
                   f"{result.step_s:.2f} s")
    return save_figure(fig, path)
