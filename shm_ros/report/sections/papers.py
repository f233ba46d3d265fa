"""The papers' tables where they apply: the bridge paper's Table 1 (the prior x fitness-weight sweep of
``shm-ros update --study``: per-mode frequency RMSE and MAC at the posterior mean) and the building
paper's Table 3 (NRMS of the predicted floor accelerations and top drift, updated against nominal).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.report.document import Figure, Section, Table
from shm_ros.report.inputs import ReportInputs
from shm_ros.report.sections._common import figure_json, plain, pyplot

TABLE3 = (("accel_floor4", "floor 4 acceleration"), ("accel_floor8", "floor 8 acceleration"),
          ("drift_top", "top story drift ratio"))


class PapersSection:
    key = "papers"
    title = "The papers' tables"
    order = 70

    def build(self, inputs: ReportInputs, fig_dir: Path) -> Section | None:
        study = (inputs.papers or {}).get("table1")
        t3 = (inputs.prediction.payload.get("table3") if inputs.prediction is not None else None) or []
        if not study and not t3:
            return None
        s = Section(self.key, self.title, [
            "The tables of the two papers this project reproduces, from this run's data: Table 1 of the "
            "bridge paper (how the prior family and the fitness weights of the frequencies (alpha) and "
            "mode shapes (beta) change the calibrated model's per-mode frequency RMSE and MAC) and Table 3 "
            "of the building paper (how well the updated model predicts the earthquake responses, NRMS %)."])
        if study and study.get("rows"):
            s.tables.append(_table1(study))
            s.figures.append(_table1_figure(study, fig_dir))
        if t3:
            s.tables.append(Table(["event", *[f"{label} NRMS % (updated / nominal)" for _, label in TABLE3]],
                                  [[r.get("window_id"), *[f"{_f(r.get(k))} / {_f(r.get(k + '_nominal'))}"
                                                          for k, _ in TABLE3]] for r in t3],
                                  "Table 3 (building paper): NRMS per event, updated / nominal model"))
            s.figures.append(_table3_figure(t3, fig_dir))
        return s


def _f(v: Any) -> str:
    return "–" if v is None or not np.isfinite(float(v)) else f"{float(v):.1f}"


def _table1(study: dict[str, Any]) -> Table:
    rows = study["rows"]
    modes = rows[0].get("modes") or study.get("modes") or []
    head = ["hyperparameter set", "configuration", *[f"RMSE mode {m}" for m in modes],
            *[f"MAC mode {m}" for m in modes]]
    body = [["prior (alpha = beta = 0.5)" if r["group"] == "prior" else "weights (normal prior)", r["configuration"],
             *[None if v is None else round(float(v), 4) for v in r["rmse"]],
             *[None if v is None else round(float(v), 3) for v in r["mac"]]] for r in rows]
    return Table(head, body, f"Table 1 (bridge paper), fitness J {study.get('fitness_j', 'averaged')} over the "
                 "windows: RMSE = relative frequency error, root mean square over windows")


def _table1_figure(study: dict[str, Any], fig_dir: Path) -> Figure:
    plt = pyplot()
    rows = study["rows"]
    modes = rows[0].get("modes") or list(range(1, len(rows[0]["rmse"]) + 1))
    rmse = np.array([[np.nan if v is None else 100 * float(v) for v in r["rmse"]] for r in rows])
    mac = np.array([[np.nan if v is None else float(v) for v in r["mac"]] for r in rows])
    labels = [r["configuration"] for r in rows]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.6))
    width = 0.8 / len(rows)
    x = np.arange(len(modes))
    for i, lab in enumerate(labels):
        a1.bar(x + i * width, rmse[i], width, label=lab)
        a2.bar(x + i * width, mac[i], width)
    for ax, yl in ((a1, "frequency RMSE, %"), (a2, "MAC")):
        ax.set_xticks(x + 0.4 - width / 2, [f"mode {m}" for m in modes], fontsize=8)
        ax.set_ylabel(yl)
    a2.set_ylim(max(0.0, float(np.nanmin(mac)) - 0.05) if np.isfinite(mac).any() else 0.0, 1.0)
    a1.legend(fontsize=6, ncol=2)
    fig.suptitle("Table 1: prior family and fitness weights against per-mode RMSE and MAC", fontsize=9)
    fig.tight_layout()
    return figure_json(fig, fig_dir, "papers_table1", "Table 1 (bridge paper) from this run's tracked modes: "
                       "per-mode frequency RMSE and MAC for each prior family and weight pair",
                       plain({"modes": modes, "configurations": labels, "rmse_pct": rmse, "mac": mac}))


def _table3_figure(rows: list[dict[str, Any]], fig_dir: Path) -> Figure:
    plt = pyplot()
    fig, axes = plt.subplots(1, len(TABLE3), figsize=(10, 3.2), squeeze=False)
    ids = [str(r.get("window_id")) for r in rows]
    x = np.arange(len(rows))
    data: dict[str, Any] = {"events": ids}
    for ax, (k, label) in zip(axes[0], TABLE3, strict=True):
        up = np.array([np.nan if r.get(k) is None else float(r[k]) for r in rows])
        nom = np.array([np.nan if r.get(k + "_nominal") is None else float(r[k + "_nominal"]) for r in rows])
        ax.bar(x - 0.2, up, 0.4, label="updated", color="tab:blue")
        ax.bar(x + 0.2, nom, 0.4, label="nominal", color="tab:red", alpha=0.7)
        ax.set_xticks(x, [i[-8:] for i in ids], fontsize=7)
        ax.set_title(label, fontsize=8)
        ax.set_ylabel("NRMS, %")
        data[k] = {"updated": up, "nominal": nom}
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("Table 3: prediction error per event, updated against nominal model", fontsize=9)
    fig.tight_layout()
    return figure_json(fig, fig_dir, "papers_table3", "Table 3 (building paper): NRMS of the predicted responses "
                       "per event, updated (blue) and nominal (red) model", plain(data))


BUILDER = PapersSection()
