"""Tracking: tracked frequencies and damping against time and against the environmental covariate,
and the novelty score with its threshold and alarms."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.report.document import Figure, Section, Table
from shm_ros.report.inputs import ReportInputs
from shm_ros.report.sections._common import datetimes, figure_csv, iso, median_or_none, pyplot, short_time_axis

#: alarm windows listed in the table (all are in the novelty CSV)
MAX_ALARMS = 30


class TrackingSection:
    key = "tracking"
    title = "Tracking"
    order = 30

    def build(self, inputs: ReportInputs, fig_dir: Path) -> Section | None:
        res = inputs.tracking
        if res is None:
            return None
        obs = res.observations
        s = Section(self.key, self.title)
        n_alarm = int(np.sum(res.novelty_alarm))
        has_novelty = bool(np.isfinite(res.novelty_score).any())
        text = (f"{obs.n_windows} windows, {obs.n_modes} tracked modes "
                f"({', '.join(f'mode {n}' for n in obs.mode_numbers)}).")
        if res.unassigned:
            text += f" {res.unassigned} identified modes matched no tracked mode."
        if has_novelty:
            thr = res.novelty_threshold
            text += (f" Novelty: first {res.n_training} windows are the training period, threshold "
                     + (f"{thr:.3g}" if np.isfinite(thr) else "none (too few training windows)")
                     + f", {n_alarm} alarms.")
        s.paragraphs.append(text)
        s.notes += list(res.notes)
        s.tables.append(self._modes_table(res))
        t = datetimes(obs.times)
        ids = res.window_ids if len(res.window_ids) == obs.n_windows else [""] * obs.n_windows
        s.figures.append(self._per_mode_figure(res, t, ids, fig_dir, "frequencies"))
        if obs.damping is not None and np.isfinite(obs.damping).any():
            s.figures.append(self._per_mode_figure(res, t, ids, fig_dir, "damping"))
        cov = obs.covariates.get(self._covariate(res))
        if cov is not None and np.isfinite(cov).any():
            s.figures.append(self._covariate_figure(res, ids, fig_dir))
        if has_novelty:
            s.figures.append(self._novelty_figure(res, t, ids, fig_dir))
            if n_alarm:
                s.tables.append(self._alarm_table(res, ids))
        return s

    @staticmethod
    def _covariate(res: Any) -> str:
        """The tracking core's default covariate when present (its result does not name it)."""
        cov = res.observations.covariates
        return "temperature_c" if "temperature_c" in cov or not cov else next(iter(cov))

    @staticmethod
    def _modes_table(res: Any) -> Table:
        obs = res.observations
        ref = {r.number: r for r in res.reference}
        env = {e.mode: e for e in res.environment}
        cols = ["mode", "reference frequency (Hz)", "found (%)", "median frequency (Hz)", "median damping (%)",
                "slope (%/unit)", "R²", "residual std (Hz)"]
        rows = []
        for k, n in enumerate(obs.mode_numbers):
            f = obs.frequencies_hz[:, k]
            d = None if obs.damping is None else median_or_none(obs.damping[:, k])
            e = env.get(n)
            rows.append([n, ref[n].frequency_hz if n in ref else None, 100 * float(np.mean(np.isfinite(f))),
                         median_or_none(f), None if d is None else 100 * d,
                         e.slope_pct_per_unit if e else None, e.r2 if e else None, e.residual_std_hz if e else None])
        return Table(cols, rows, "Tracked modes (slope and R² of the frequency against the covariate over the "
                     "training windows)")

    @staticmethod
    def _per_mode_figure(res: Any, t: list, ids: list[str], fig_dir: Path, what: str) -> Figure:
        plt = pyplot()
        obs = res.observations
        vals = obs.frequencies_hz if what == "frequencies" else 100 * np.asarray(obs.damping)
        n_m = max(obs.n_modes, 1)
        n_col = 1 if n_m < 4 else 2
        n_row = -(-n_m // n_col)
        fig, axes = plt.subplots(n_row, n_col, figsize=(11, 1.2 + 1.6 * n_row), sharex=True, squeeze=False)
        alarm = np.asarray(res.novelty_alarm, bool)
        ylabel = "frequency (Hz)" if what == "frequencies" else "damping (%)"
        for k, ax in enumerate(axes.flat):
            if k >= obs.n_modes:
                ax.set_visible(False)
                continue
            ax.plot(t, vals[:, k], ".-", ms=4, lw=0.6, color=f"C{k % 10}")
            for ta in [ti for ti, a in zip(t, alarm, strict=True) if a]:
                ax.axvline(ta, color="tab:red", lw=0.6, alpha=0.5)
            ax.set_title(f"mode {obs.mode_numbers[k]}", fontsize=9, loc="left")
            ax.set_ylabel(ylabel, fontsize=8)
            ax.grid(alpha=0.3)
        for ax in axes[-1]:
            short_time_axis(ax)
        fig.suptitle(f"tracked {what} against time" + (" (red: novelty alarms)" if alarm.any() else ""))
        unit = "hz" if what == "frequencies" else "damping"
        raw = obs.frequencies_hz if what == "frequencies" else np.asarray(obs.damping)
        rows = [[iso(float(obs.times[i])), ids[i], *raw[i]] for i in range(obs.n_windows)]
        return figure_csv(fig, fig_dir, f"tracking_{what}", f"Tracked {what} of every mode against time.",
                          ["time", "window_id", *[f"mode{n}_{unit}" for n in obs.mode_numbers]], rows)

    def _covariate_figure(self, res: Any, ids: list[str], fig_dir: Path) -> Figure:
        plt = pyplot()
        obs = res.observations
        name = self._covariate(res)
        x = np.asarray(obs.covariates[name], float)
        env = {e.mode: e for e in res.environment}
        fig, ax = plt.subplots(figsize=(10, 4.5))
        unit = "°C" if name == "temperature_c" else "unit"
        for k, n in enumerate(obs.mode_numbers):
            f = obs.frequencies_hz[:, k]
            med = median_or_none(f)
            if med is None:
                continue
            e = env.get(n)
            label = f"mode {n}" + (f": {e.slope_pct_per_unit:+.3f} %/{unit}, R² {e.r2:.2f}"
                                   if e is not None and np.isfinite(e.slope_pct_per_unit) else "")
            line = ax.plot(x, f / med, "o", ms=4, label=label)[0]
            if e is not None and np.isfinite(e.slope_hz_per_unit) and np.isfinite(x).any():
                xx = np.array([np.nanmin(x), np.nanmax(x)])
                ax.plot(xx, (e.intercept_hz + e.slope_hz_per_unit * xx) / med, "-", lw=1, color=line.get_color())
        ax.set_xlabel(name.replace("_c", " (°C)") if name == "temperature_c" else name)
        ax.set_ylabel("frequency / median")
        ax.set_title(f"tracked frequencies against {name} (lines: environmental model)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="best")
        rows = [[iso(float(obs.times[i])), ids[i], x[i], *obs.frequencies_hz[i]] for i in range(obs.n_windows)]
        return figure_csv(fig, fig_dir, "tracking_temperature" if name == "temperature_c" else "tracking_covariate",
                          f"Tracked frequencies (relative to their median) against {name}, with the "
                          "environmental model fitted on the training windows.",
                          ["time", "window_id", name, *[f"mode{n}_hz" for n in obs.mode_numbers]], rows)

    @staticmethod
    def _novelty_figure(res: Any, t: list, ids: list[str], fig_dir: Path) -> Figure:
        plt = pyplot()
        score = np.asarray(res.novelty_score, float)
        alarm = np.asarray(res.novelty_alarm, bool)
        fig, ax = plt.subplots(figsize=(10, 4))
        ax.plot(t, score, ".-", ms=4, lw=0.6, color="0.3", label="novelty score")
        if np.isfinite(res.novelty_threshold):
            ax.axhline(res.novelty_threshold, color="tab:red", lw=1, label=f"threshold {res.novelty_threshold:.3g}")
        if alarm.any():
            t_alarm = [ti for ti, a in zip(t, alarm, strict=True) if a]
            ax.plot(t_alarm, score[alarm], "o", ms=7, mfc="none", mec="tab:red", label=f"alarms ({int(alarm.sum())})")
        if res.n_training and t:
            ax.axvspan(t[0], t[min(res.n_training, len(t)) - 1], color="tab:green", alpha=0.12, label="training")
        if np.nanmin(score) > 0:
            ax.set_yscale("log")
        ax.set_ylabel("mean squared z of the residuals")
        ax.set_title("novelty score")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper left")
        short_time_axis(ax)
        rows = [[iso(float(res.observations.times[i])), ids[i], score[i], bool(alarm[i]), i < res.n_training,
                 res.novelty_threshold] for i in range(score.size)]
        return figure_csv(fig, fig_dir, "tracking_novelty",
                          "Novelty score of every window (environmental-model residuals), threshold "
                          "and alarms; the shaded span is the training period.",
                          ["time", "window_id", "score", "alarm", "training", "threshold"], rows)

    @staticmethod
    def _alarm_table(res: Any, ids: list[str]) -> Table:
        score = np.asarray(res.novelty_score, float)
        idx = np.flatnonzero(np.asarray(res.novelty_alarm, bool))
        rows = [[ids[i] or str(i), iso(float(res.observations.times[i])), score[i]] for i in idx[:MAX_ALARMS]]
        cap = "Novelty alarms" + (f" (first {MAX_ALARMS} of {idx.size})" if idx.size > MAX_ALARMS else "")
        return Table(["window", "time (UTC)", "score"], rows, cap)


BUILDER = TrackingSection()
