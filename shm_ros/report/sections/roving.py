"""Roving campaign: the structure with its points, references and setups, and the glued shapes with
their uncertainty (modes.json of a structure with roving sensors, docs/interfaces.md section 8)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from shm_ros.report.document import Section, Table
from shm_ros.report.inputs import ReportInputs
from shm_ros.report.sections._common import figure_csv, pyplot

N_SHAPES = 4  # global modes drawn


class RovingSection:
    key = "roving"
    title = "Roving sensors: setups and global mode shapes"
    order = 25

    def build(self, inputs: ReportInputs, fig_dir: Path) -> Section | None:
        doc = inputs.roving
        if doc is None:
            return None
        setups, modes, info = doc.get("setups", []), doc.get("global_modes", []), doc.get("roving", {})
        refs = setups[0]["references"] if setups else []
        s = Section(self.key, self.title)
        s.paragraphs.append(
            f"{len(setups)} setups glued through the references {', '.join(refs)}: "
            f"{len(modes)} global modes; {info.get('moving_samples', 0)} samples recorded while a roving "
            f"sensor moved were left out; clock offset of the roving sensors "
            f"{1e3 * (info.get('clock_offset_s') or float('nan')):.1f} ms.")
        s.notes += list(info.get("errors", []))
        s.tables.append(Table(["setup", "points", "samples", "clock offset (ms)"],
                              [[u["id"], ", ".join(f"{k}: {v}" for k, v in u["points"].items()), u["samples"],
                                1e3 * u["clock_offset_s"] if u.get("clock_offset_s") is not None else None]
                               for u in setups], "Setups: where each roving sensor stood"))
        s.tables.append(Table(["mode", "frequency (Hz)", "damping ratio", "setups found", "notes"],
                              [[k + 1, m["frequency_hz"], m["damping_ratio"], m["setups_found"],
                                "; ".join(m.get("notes", []))] for k, m in enumerate(modes)], "Global modes"))
        pos = info.get("positions", {})
        if modes and pos:
            s.figures.append(self._shapes(modes[:N_SHAPES], pos, refs, fig_dir))
        return s

    @staticmethod
    def _shapes(modes: list[dict], pos: dict[str, list[float]], refs: list[str], fig_dir: Path):
        plt = pyplot()
        fig, axes = plt.subplots(len(modes), 1, figsize=(7, 1.8 * len(modes)), sharex=True, squeeze=False)
        rows = []
        for ax, (k, m) in zip(axes[:, 0], enumerate(modes), strict=True):
            keys = sorted((p for p in m["shape"] if p in pos and m["shape"][p] is not None), key=lambda p: pos[p][0])
            x = np.array([pos[p][0] for p in keys])
            v = np.array([m["shape"][p] for p in keys])
            e = np.array([m["shape_std"].get(p) or 0.0 for p in keys])
            ax.errorbar(x, v, yerr=2 * e, fmt="o-", ms=3, capsize=2, label="points (±2 std)")
            is_ref = np.array([p in refs for p in keys])
            ax.plot(x[is_ref], v[is_ref], "s", color="C3", label="references")
            ax.axhline(0.0, color="0.7", lw=0.5)
            ax.set_ylabel(f"{m['frequency_hz']:.3f} Hz")
            rows += [[k + 1, p, float(xx), float(vv), float(ee)] for p, xx, vv, ee in zip(keys, x, v, e, strict=True)]
        axes[0, 0].legend(fontsize=7, loc="upper right")
        axes[-1, 0].set_xlabel("position along the structure (m)")
        return figure_csv(fig, fig_dir, "roving_shapes", "Glued mode shapes over every point visited (±2 std: "
                          "the references' scale and repeated points)", ["mode", "point", "x_m", "shape", "std"], rows)


BUILDER = RovingSection()
