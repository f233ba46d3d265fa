"""Tracked frequencies against time and against the environmental covariate, with the novelty
score and its threshold."""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from shm_ros.core.tracking import TrackingResult  # noqa: E402
from shm_ros.report.figures import save_figure  # noqa: E402


def plot_tracking(res: TrackingResult, path: str | Path, covariate: str = "temperature_c") -> Path:
    obs = res.observations
    t = [datetime.fromtimestamp(float(x), tz=timezone.utc) for x in obs.times]
    x = obs.covariates.get(covariate)
    fig, axes = plt.subplots(3 if x is not None else 2, 1, figsize=(10, 9), dpi=100)
    ax = axes[0]
    for k, n in enumerate(obs.mode_numbers):
        ax.plot(t, obs.frequencies_hz[:, k], ".", ms=2, label=f"mode {n}")
    ax.set_ylabel("frequency (Hz)")
    ax.set_title("tracked modes")
    ax.legend(fontsize=7, ncol=min(6, obs.n_modes), loc="upper right")
    if x is not None:
        unit = "°C" if covariate == "temperature_c" else "unit"
        ax = axes[1]
        for k, (n, fit) in enumerate(zip(obs.mode_numbers, res.environment, strict=False)):
            f = obs.frequencies_hz[:, k]
            ax.plot(x, f / np.nanmedian(f), ".", ms=2, label=f"mode {n}: "
                    f"{fit.slope_pct_per_unit:+.3f} %/{unit}, R² {fit.r2:.2f}")
        ax.set_xlabel(covariate)
        ax.set_ylabel("frequency / median")
        ax.legend(fontsize=7, loc="upper right")
    ax = axes[-1]
    ax.semilogy(t, res.novelty_score, ".", ms=2, color="0.3", label="novelty score")
    ax.axhline(res.novelty_threshold, color="tab:red", lw=1, label="threshold")
    if res.n_training:
        ax.axvspan(t[0], t[min(res.n_training, len(t)) - 1], color="tab:green", alpha=0.1,
                   label="training")
    ax.set_ylabel("mean squared z")
    ax.legend(fontsize=7, loc="upper left")
    return save_figure(fig, path)
