"""Predicted-vs-measured figures of one event: every measured channel with its predictive band."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np


def plot_event(pred: Any, path: str | Path) -> Path:
    """One panel per measured channel: measured, predictive mean and band, nominal model (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    chans = [c for c in pred.channels if c.measured]
    fig, axes = plt.subplots(max(1, len(chans)), 1, figsize=(9, 1.9 * max(1, len(chans))), sharex=True,
                             squeeze=False)
    t = np.arange(chans[0].mean.size) / pred.fs if chans else np.zeros(0)
    for ax, c in zip(axes[:, 0], chans, strict=False):
        ax.fill_between(t, c.lower, c.upper, color="tab:blue", alpha=0.25, lw=0, label="95 % band")
        ax.plot(t, c.values, color="k", lw=0.6, label="measured")
        ax.plot(t, c.mean, color="tab:blue", lw=0.8, label="updated model")
        ax.plot(t, c.nominal, color="tab:red", lw=0.6, alpha=0.7, label="nominal model")
        ax.axvspan(pred.strong.start / pred.fs, pred.strong.stop / pred.fs, color="0.9", zorder=-1)
        s = c.scores
        ax.set_ylabel(f"{c.name}\nm/s²")
        ax.set_title(f"NRMS {s['nrms_pct']:.1f} % (nominal {s['nrms_pct_nominal']:.1f} %), band holds "
                     f"{100 * (s['coverage_95'] or 0):.0f} %", fontsize=8, loc="left")
    axes[0, 0].legend(fontsize=7, ncol=4, loc="upper right")
    axes[-1, 0].set_xlabel("time from window start, s (grey: strong motion)")
    fig.suptitle(f"{pred.window_id}: predicted vs measured", fontsize=9)
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out
