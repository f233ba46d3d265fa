"""Figures of the explain worked example (docs/explain.md) from its output folder.

    python examples/explain_example_figures.py OUT [FIG_DIR]     (default FIG_DIR: OUT/explain)

Reads OUT/truth_modes.csv (the table explain read), OUT/truth.json (the hidden effect),
OUT/explain/verdict.json and explain_series.json (the fitted form); writes explain_example_{data,form,candidates}.png.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from shm_ros.io.tables import read_tracked_modes  # noqa: E402


def bilinear(t: np.ndarray, p: dict[str, float], t_ref: float) -> np.ndarray:
    return 1.0 + p["alpha_per_c"] * (t - t_ref) + p["below_per_c"] * np.minimum(t - p["knee_c"], 0.0)


def main(out: Path, fig_dir: Path) -> None:
    obs = read_tracked_modes(out / "truth_modes.csv")
    verdict = json.loads((out / "explain" / "verdict.json").read_text())
    series = json.loads((out / "explain" / "explain_series.json").read_text())
    truth = json.loads((out / "truth.json").read_text())["hidden_effects"][0]["parameters"]
    temp = np.asarray(obs.covariates["temperature_c"], float)
    best = next(m for m in verdict["missing_physics"] if m["name"] != "unmodelled_modes")
    fig_dir.mkdir(parents=True, exist_ok=True)

    # 1. what the data show: the paired modes' frequencies against the measured temperature
    fig, ax = plt.subplots(figsize=(6.0, 3.2))
    for m in series["mode_numbers"]:
        f = obs.frequencies_hz[:, obs.mode_numbers.index(m)]
        ax.plot(temp, 100 * (f / np.nanmedian(f) - 1), ".", ms=2.5, label=f"mode {m}")
    if "knee_c" in best["parameters"]:
        ax.axvline(best["parameters"]["knee_c"], color="k", lw=0.8, ls="--", label="fitted knee")
    ax.set_xlabel("measured air temperature, degC")
    ax.set_ylabel("frequency - median, %")
    ax.set_title("tracked modes paired with the model: frequency against temperature", fontsize=9)
    ax.legend(fontsize=7, ncol=3)
    fig.tight_layout()
    fig.savefig(fig_dir / "explain_example_data.png", dpi=80)

    # 2. the selected physics in its fitted form, with the simulator's hidden truth
    t = np.linspace(np.nanmin(temp), np.nanmax(temp), 200)
    t_ref = float(np.nanmedian(temp))
    fig, ax = plt.subplots(figsize=(6.0, 3.2))
    form = series["form"]  # the accepted effect's factor per window against temperature, as fitted
    x, f = np.asarray(form["x"], float), np.asarray(form["y"], float)
    ax.plot(x, f / np.interp(t_ref, x, f), color="tab:blue", label=f"fitted: {best['form']}")
    ax.plot(t, bilinear(t, truth, truth["t_ref_c"]) / bilinear(np.array([t_ref]), truth, truth["t_ref_c"]),
            "k--", lw=1, label="hidden truth (simulator)")
    ax.set_xlabel("air temperature, degC")
    ax.set_ylabel("deck stiffness factor")
    ax.set_title("temperature-dependent stiffness: fitted form and the hidden truth", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(fig_dir / "explain_example_form.png", dpi=80)

    # 3. every candidate tried: evidence gain against the threshold
    cands = sorted(verdict["candidates"], key=lambda c: c["log_evidence_gain"])
    fig, ax = plt.subplots(figsize=(6.0, 0.45 * len(cands) + 1.0))
    y = np.arange(len(cands))
    ax.barh(y, [c["log_evidence_gain"] for c in cands],
            color=["tab:green" if c["accepted"] else "0.6" for c in cands])
    ax.set_yticks(y, [c["label"].split("/", 1)[1] for c in cands], fontsize=7)
    ax.axvline(verdict["threshold"]["log_bayes_factor"], color="tab:red", lw=1, label="threshold")
    ax.set_xscale("symlog", linthresh=10)
    ax.set_xlabel("log evidence gain, nats (green: accepted)")
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(fig_dir / "explain_example_candidates.png", dpi=80)


if __name__ == "__main__":
    o = Path(sys.argv[1])
    main(o, Path(sys.argv[2]) if len(sys.argv) > 2 else o / "explain")
