"""Identification: stabilization diagrams of sample windows, the modes found across windows, and
the comparison with the simulator's truth when there is one."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.core.types import ModalEstimate
from shm_ros.report.document import Figure, Section, Table
from shm_ros.report.identify_summary import match_to_truth
from shm_ros.report.inputs import IdentifyInputs, ReportInputs
from shm_ros.report.sections._common import (
    datetimes,
    figure_csv,
    iso_ns,
    pyplot,
    short_time_axis,
    write_csv,
    write_json,
)

#: relative frequency gap that separates two clusters of modes across windows
CLUSTER_GAP = 0.01
#: stabilization diagrams shown (first, middle and last window that has one)
N_DIAGRAMS = 3
#: a cluster found in fewer windows than this fraction is counted, not listed
MIN_PRESENCE = 0.1


def cluster_modes(estimates: list[ModalEstimate], gap: float = CLUSTER_GAP) -> list[list[tuple[int, Any]]]:
    """Modes of all windows grouped by frequency: sorted, a new group where the next frequency is
    more than ``gap`` (relative) above the previous one. Each entry is (window index, Mode)."""
    pool = sorted(((i, m) for i, e in enumerate(estimates) for m in e.modes
                   if np.isfinite(m.frequency_hz)), key=lambda im: im[1].frequency_hz)
    groups: list[list[tuple[int, Any]]] = []
    for item in pool:
        if groups and item[1].frequency_hz <= groups[-1][-1][1].frequency_hz * (1 + gap):
            groups[-1].append(item)
        else:
            groups.append([item])
    return groups


class IdentifySection:
    key = "identify"
    title = "Identification"
    order = 20

    def build(self, inputs: ReportInputs, fig_dir: Path) -> Section | None:
        ident = inputs.identify
        if ident is None or (not ident.estimates and inputs.roving):
            return None  # a roving campaign's modes.json: the roving section shows its setups
        ests = sorted(ident.estimates, key=lambda e: e.start_ns)
        s = Section(self.key, self.title)
        n_modes = [len(e.modes) for e in ests]
        methods = sorted({e.method for e in ests}) or [ident.method]
        s.paragraphs.append(
            f"{len(ests)} windows identified ({', '.join(m for m in methods if m)}); "
            + (f"{min(n_modes)} to {max(n_modes)} modes per window (median {np.median(n_modes):g})."
               if ests else "no modes."))
        if not ests:
            return s
        s.tables.append(self._modes_table(ests, fig_dir, s))
        s.figures += self._diagrams(ident, ests, fig_dir)
        if not ident.diagrams:
            s.notes.append("stabilization diagrams need the windows' samples; only the modal estimates "
                           "were given, so the frequencies per window are shown instead")
        s.figures.append(self._frequencies_figure(ests, inputs.truth, fig_dir))
        if inputs.truth:
            s.tables.append(self._truth_table(ests, inputs.truth, fig_dir, s))
        return s

    @staticmethod
    def _modes_table(ests: list[ModalEstimate], fig_dir: Path, s: Section) -> Table:
        cols = ["cluster", "median frequency (Hz)", "frequency std (Hz)", "median damping (%)",
                "median MPC", "windows found", "found (%)"]
        rows: list[list[Any]] = []
        for k, g in enumerate(cluster_modes(ests), 1):
            f = np.array([m.frequency_hz for _, m in g])
            z = np.array([m.damping_ratio for _, m in g], float)
            mpc = np.array([m.mpc for _, m in g], float)
            n_win = len({i for i, _ in g})
            rows.append([k, float(np.median(f)), float(np.std(f)) if f.size > 1 else None,
                         100 * float(np.nanmedian(z)) if np.isfinite(z).any() else None,
                         float(np.nanmedian(mpc)) if np.isfinite(mpc).any() else None,
                         n_win, 100.0 * n_win / len(ests)])
        data = write_csv(fig_dir / "identify_modes.csv", cols, rows)
        keep = [r for r in rows if r[-1] >= 100 * MIN_PRESENCE] if len(ests) >= 10 else rows
        if len(keep) < len(rows):
            s.notes.append(f"{len(rows) - len(keep)} further clusters found in fewer than "
                           f"{100 * MIN_PRESENCE:.0f} % of the windows are only in the CSV")
        return Table(cols, keep, f"Modes across windows (clusters of frequencies {100 * CLUSTER_GAP:g} % apart)",
                     data)

    @staticmethod
    def _diagrams(ident: IdentifyInputs, ests: list[ModalEstimate], fig_dir: Path) -> list[Figure]:
        from shm_ros.report.stabilization import plot_stabilization

        have = [e for e in ests if e.window_id in ident.diagrams]
        if not have:
            return []
        picks = sorted({0, len(have) // 2, len(have) - 1})[:N_DIAGRAMS]
        out = []
        for n, idx in enumerate(picks, 1):
            e = have[idx]
            d = ident.diagrams[e.window_id]
            name = f"identify_stabilization_{n}"
            png = plot_stabilization(d, fig_dir / f"{name}.png",
                                     f"{iso_ns(e.start_ns)}  {e.method}  ({len(e.modes)} modes)")
            data = write_json(fig_dir / f"{name}.json", _diagram_data(e, d))
            out.append(Figure(png, data, f"Stabilization diagram of window {e.window_id}: poles per model "
                              "order by how far they passed the stability filters; red lines are the "
                              "picked modes."))
        return out

    @staticmethod
    def _frequencies_figure(ests: list[ModalEstimate], truth: dict[str, Any] | None, fig_dir: Path) -> Figure:
        plt = pyplot()
        fig, ax = plt.subplots(figsize=(10, 4.5))
        t = datetimes(e.start_ns / 1e9 for e in ests)
        xs = [ti for ti, e in zip(t, ests, strict=True) for _ in e.modes]
        f = [m.frequency_hz for e in ests for m in e.modes]
        z = [100 * m.damping_ratio for e in ests for m in e.modes]
        sc = ax.scatter(xs, f, c=z, s=18, cmap="viridis", label="identified", zorder=3)
        fig.colorbar(sc, ax=ax, label="damping (%)", fraction=0.04)
        rows: list[list[Any]] = [[e.window_id, iso_ns(e.start_ns), "identified", m.frequency_hz, m.damping_ratio,
                                  m.mpc] for e in ests for m in e.modes]
        by_start = {int(w["start_ns"]): w for w in (truth or {}).get("windows", [])}
        tx, tf = [], []
        for ti, e in zip(t, ests, strict=True):
            tw = by_start.get(e.start_ns)
            if tw is None:
                continue
            for k, fk in enumerate(tw.get("frequencies_hz", [])):
                tx.append(ti)
                tf.append(fk)
                dk = tw.get("damping_ratios", [None] * (k + 1))
                rows.append([e.window_id, iso_ns(e.start_ns), "truth", fk, dk[k] if k < len(dk) else None, None])
        if tf:
            ax.scatter(tx, tf, marker="_", s=300, color="tab:red", lw=1.5, label="truth", zorder=2)
        ax.set_ylabel("frequency (Hz)")
        ax.set_title("identified frequencies per window")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left", fontsize=8)
        short_time_axis(ax)
        return figure_csv(fig, fig_dir, "identify_frequencies",
                          "Frequencies identified in every window, coloured by damping"
                          + ("; red bars are the simulator's true frequencies." if tf else "."),
                          ["window_id", "start", "kind", "frequency_hz", "damping_ratio", "mpc"], rows)

    @staticmethod
    def _truth_table(ests: list[ModalEstimate], truth: dict[str, Any], fig_dir: Path, s: Section) -> Table:
        n_true = max((len(w.get("frequencies_hz", [])) for w in truth.get("windows", [])), default=0)
        matches = match_to_truth(ests, truth, n_modes=n_true)
        cols = ["true mode", "true frequency (Hz)", "found in windows", "mean error (%)", "max |error| (%)",
                "mean MAC"]
        raw = []
        rows = []
        for k in range(n_true):
            tf = [m.true_hz[k] for m in matches if k < len(m.true_hz)]
            err = [float(e) for m in matches if k < len(m.error_pct) and (e := m.error_pct[k]) is not None]
            mac = [float(c) for m in matches if k < len(m.mac) and (c := m.mac[k]) is not None]
            found = sum(1 for m in matches if k < len(m.found_hz) and m.found_hz[k] is not None)
            rows.append([k + 1, float(np.median(tf)) if tf else None, f"{found} of {len(matches)}",
                         float(np.mean(err)) if err else None, float(np.max(np.abs(err))) if err else None,
                         float(np.mean(mac)) if mac else None])
        for m in matches:
            for k, (tf_k, ff, ee, cc) in enumerate(zip(m.true_hz, m.found_hz, m.error_pct, m.mac, strict=True), 1):
                raw.append([m.window_id, k, tf_k, ff, ee, cc])
        data = write_csv(fig_dir / "identify_truth.csv",
                         ["window_id", "true_mode", "true_hz", "found_hz", "error_pct", "mac"], raw)
        if not matches:
            s.notes.append("truth.json has no window starting where an identified window starts")
        return Table(cols, rows, "Against the simulator's truth (closest identified mode within 5 %)", data)


def _diagram_data(e: ModalEstimate, d: Any) -> dict[str, Any]:
    p, fl = d.poles, d.flags
    out: dict[str, Any] = {
        "window_id": e.window_id, "start": iso_ns(e.start_ns),
        "poles": {"order": p.order, "frequency_hz": p.frequency_hz, "damping_ratio": p.damping_ratio,
                  "mpc": fl.mpc, "stable_frequency": fl.stable_freq, "stable": fl.stable,
                  "candidate": fl.candidates(True)},
        "picked": [{"frequency_hz": m.frequency_hz, "damping_ratio": m.damping_ratio, "mpc": m.mpc,
                    "n_poles": m.n_poles, "order": m.representative_order} for m in d.picked],
    }
    if d.spectrum_hz is not None and d.spectrum is not None:
        out["spectrum"] = {"frequency_hz": d.spectrum_hz, "value": d.spectrum}
    return out


BUILDER = IdentifySection()
