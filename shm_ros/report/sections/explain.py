"""Explanation (missing physics): the verdict of ``shm-ros explain`` (docs/explain.md).

What the engineer needs to see: where the misfit was and what it followed (residuals against each
covariate and against time, before and after adding the selected physics, held-out windows marked),
the selected physics in its fitted form (e.g. stiffness against temperature with the knee), every
candidate tried with its support, and the fit before / after / on held-out windows.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.core.explain.fit_ratio import fit_sentence
from shm_ros.report.document import Figure, Section, Table
from shm_ros.report.inputs import ReportInputs
from shm_ros.report.sections._common import figure_json, plain, pyplot


class ExplainSection:
    key = "explain"
    title = "Explanation (missing physics)"
    order = 60

    def build(self, inputs: ReportInputs, fig_dir: Path) -> Section | None:
        x = inputs.explain
        if x is None:
            return None
        v, series = x.verdict, x.series
        s = Section(self.key, self.title, _paragraphs(v), notes=list(x.notes))
        s.tables.append(_fit_table(v))
        if (v.get("fit") or {}).get("residual_whiteness"):
            s.tables.append(_whiteness_table(v["fit"]["residual_whiteness"]))
        tried = v.get("candidates") or v.get("missing_physics") or []
        if tried:
            s.tables.append(_candidates_table(tried))
        s.figures += _figures(v, series, fig_dir)
        if series.get("events"):  # the time-domain path (earthquake series)
            s.figures += _event_figures(series["events"], fig_dir)
            if (series.get("form") or {}).get("x") is not None:
                s.figures.append(_form_figure(series["form"], fig_dir))
        if not s.figures and inputs.tracking is not None:  # a series without residuals: what the data follow
            fig = _tracked_covariate_figure(inputs.tracking.observations, v, series, fig_dir)
            if fig is not None:
                s.figures.append(fig)
        return s


def _tracked_covariate_figure(obs: Any, v: dict[str, Any], series: dict[str, Any], fig_dir: Path) -> Figure | None:
    """The explained modes' frequencies (change from their mean, %) against each covariate the
    mismatch correlates with: what the missing physics was found to follow."""
    corr = (v.get("mismatch") or {}).get("covariates") or {}
    covs = {k: np.asarray(obs.covariates[k], dtype=float) for k in corr if k in getattr(obs, "covariates", {})}
    modes = [m for m in (series.get("mode_numbers") or obs.mode_numbers) if m in obs.mode_numbers]
    if not covs or not modes:
        return None
    plt = pyplot()
    fig, axes = plt.subplots(1, len(covs), figsize=(3.4 * len(covs) + 1, 3.2), squeeze=False, sharey=True)
    data: dict[str, Any] = {"mode_numbers": modes, "covariates": covs, "change_pct": {}}
    for m in modes:
        f = np.asarray(obs.frequencies_hz[:, obs.mode_numbers.index(m)], dtype=float)
        change = 100 * (f / np.nanmean(f) - 1)
        data["change_pct"][m] = change
        for ax, c in zip(axes[0], covs.values(), strict=True):
            ax.plot(c, change, ".", ms=3, label=f"mode {m}")
    for ax, name in zip(axes[0], covs, strict=True):
        ax.set_xlabel(name)
        ax.set_title(f"correlation with the misfit {float(corr[name]):+.2f}", fontsize=8)
    axes[0, 0].set_ylabel("frequency change from the mean, %")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("what the mismatch follows: the explained modes' frequencies against each covariate", fontsize=9)
    fig.tight_layout()
    return figure_json(fig, fig_dir, "explain_tracked_covariates", "The explained modes' frequencies against each "
                       "covariate, with the covariate's correlation with the model's misfit", plain(data))


def _paragraphs(v: dict[str, Any]) -> list[str]:
    out = [f"Mismatch: {v.get('mismatch', {}).get('summary', '–')}"]
    if v.get("status", "ok") != "ok":
        return [*out, f"Status: {v['status']} — nothing was analysed."]
    out.append(fit_sentence(v).capitalize() + ".")
    found = v.get("missing_physics", [])
    if not found and v.get("model_fits"):
        out.append("Missing physics: none — the calibrated nominal model explains the recordings "
                   "within their scatter (no candidate cleared the acceptance threshold).")
    elif not found:
        out.append("Missing physics: none named — no candidate cleared the acceptance threshold, yet the "
                   "model does not fit within the scatter (see the fit ratio): what is missing is not in the "
                   "vocabulary, or the data are too few to tell.")
    for i, m in enumerate(found, 1):
        where = f" at {m['where']}" if m.get("where") else ""
        when = f", from {m['time']}" if m.get("time") else ""
        tied = f" (the data cannot tell it from: {', '.join(m['tied_with'])})" if m.get("tied_with") else ""
        flags = "".join([" Its functional form does not fit what it explains (structure is left in its residual)."
                         if m.get("form_fits") is False else "",
                         f" Downgraded by the {str(m['downgraded_by']).replace('_', '-')}: not a confident name."
                         if m.get("downgraded_by") else ""])
        out.append(f"{i}. {m['name']}{where}{when}: {m.get('form', '')}; log evidence gain "
                   f"{m.get('log_evidence_gain', float('nan')):.1f} nats{tied}. {m.get('explanation', '')}{flags}")
    u = v.get("unexplained_structure")
    if u:
        out.append(f"Unexplained structure: a catch-all discrepancy beats every named candidate ({u}).")
    thr = v.get("threshold") or {}
    if thr:
        out.append(f"Acceptance threshold: {thr.get('log_bayes_factor', thr.get('value', '–'))} nats "
                   f"({thr.get('source', thr.get('calibration', 'shipped calibration'))}).")
    return out


def _fit_table(v: dict[str, Any]) -> Table:
    f = v.get("fit", {})
    rows = []
    for label, d in (("all windows, before", f.get("before", {})), ("all windows, after", f.get("after", {})),
                     ("held out, before", f.get("held_out", {}).get("before", {})),
                     ("held out, after", f.get("held_out", {}).get("after", {}))):
        rows.append([label, d.get("frequency_rmse_pct"), d.get("mac_mean"), d.get("damping_rmse_pct"),
                     d.get("nrms_pct")])
    return Table(["fit", "frequency RMSE %", "mean MAC", "damping RMSE (points)", "NRMS %"], rows,
                 "Fit of the model before and after adding the accepted physics")


def _whiteness_table(w: dict[str, Any]) -> Table:
    rows = [[m, b, a, pb, pa, "yes" if m in w.get("still_structured", []) else ""] for m, b, a, pb, pa in zip(
        w["mode_numbers"], w["lag1_before"], w["lag1_after"], w["ljung_box_p_before"], w["ljung_box_p_after"],
        strict=True)]
    return Table(["mode", "lag-1 autocorrelation before", "after", "Ljung-Box p before", "after",
                  "structure left"], rows,
                 "Is what remains noise? The misfit's autocorrelation from window to window, per mode, before and "
                 "after the accepted physics (white: about 0 and p not small)")


def _candidates_table(tried: list[dict[str, Any]]) -> Table:
    def gain(c: dict[str, Any]) -> float:
        g = c.get("log_evidence_gain")
        return -np.inf if g is None or not np.isfinite(float(g)) else float(g)

    rows = [[c.get("name"), c.get("where"), c.get("form"), c.get("log_evidence_gain"),
             c.get("log_evidence_gain_err"), c.get("log_evidence_gain_check"),
             "failed" if c.get("failed") else c.get("accepted"), c.get("form_fits"), c.get("downgraded_by"),
             "; ".join(c.get("reasons", []))] for c in sorted(tried, key=lambda c: -gain(c))]
    return Table(["candidate", "where", "fitted form", "log evidence gain", "± (s.e.)", "second estimator",
                  "accepted", "form fits", "downgraded by", "why"], rows, "Every candidate tried, most supported first")


def _arr(series: dict[str, Any], key: str) -> np.ndarray | None:
    v = series.get(key)
    if v is None:
        return None
    return np.asarray(v, dtype=float)


def _figures(v: dict[str, Any], series: dict[str, Any], fig_dir: Path) -> list[Figure]:
    figs: list[Figure] = []
    before, after = _arr(series, "log_residual_before"), _arr(series, "log_residual_after")
    t = _arr(series, "times_s")
    if before is None or t is None or before.ndim != 2:
        return figs
    after = before if after is None else after
    train = np.asarray(series.get("train", np.ones(t.size, bool)), dtype=bool)
    modes = series.get("mode_numbers") or list(range(1, before.shape[1] + 1))
    covs = {k: np.asarray(c, dtype=float) for k, c in (series.get("covariates") or {}).items()
            if np.isfinite(np.asarray(c, dtype=float)).sum() > 2}
    figs.append(_time_figure(t, before, after, train, modes, fig_dir))
    if covs:
        figs.append(_covariate_figure(covs, before, after, modes, fig_dir))
    form = series.get("form")
    if form and form.get("x") is not None:
        figs.append(_form_figure(form, fig_dir))
    return figs


def _time_figure(t, before, after, train, modes, fig_dir) -> Figure:
    plt = pyplot()
    k = before.shape[1]
    fig, axes = plt.subplots(k, 1, figsize=(9, 1.6 * k + 0.6), sharex=True, squeeze=False)
    days = (t - t[0]) / 86400.0
    for j, ax in enumerate(axes[:, 0]):
        ax.plot(days, 100 * before[:, j], ".", ms=2, color="0.6", label="before")
        ax.plot(days[train], 100 * after[train, j], ".", ms=2, color="tab:blue", label="after (fitted)")
        ax.plot(days[~train], 100 * after[~train, j], ".", ms=3, color="tab:orange", label="after (held out)")
        ax.axhline(0, color="k", lw=0.5)
        ax.set_ylabel(f"mode {modes[j]}\n%")
    axes[0, 0].legend(fontsize=7, ncol=3, loc="upper right")
    axes[-1, 0].set_xlabel("days from the first window")
    fig.suptitle("frequency misfit ln(f_obs / f_model) against time, before and after", fontsize=9)
    fig.tight_layout()
    data = {"days": days, "train": train, "mode_numbers": modes, "residual_before_pct": 100 * before,
            "residual_after_pct": 100 * after}
    return figure_json(fig, fig_dir, "explain_residuals_time",
                       "Frequency misfit of every tracked mode against time, before (grey) and after adding the "
                       "accepted physics (blue: windows used to fit it; orange: held-out windows)", plain(data))


def _covariate_figure(covs, before, after, modes, fig_dir) -> Figure:
    plt = pyplot()
    names = list(covs)
    k = before.shape[1]
    fig, axes = plt.subplots(k, len(names), figsize=(3.4 * len(names) + 1, 1.6 * k + 0.6), squeeze=False,
                             sharey="row")
    for i, name in enumerate(names):
        c = covs[name]
        for j in range(k):
            ax = axes[j, i]
            ax.plot(c, 100 * before[:, j], ".", ms=2, color="0.6")
            ax.plot(c, 100 * after[:, j], ".", ms=2, color="tab:blue")
            ax.axhline(0, color="k", lw=0.5)
            if i == 0:
                ax.set_ylabel(f"mode {modes[j]}\n%")
        axes[-1, i].set_xlabel(name)
    fig.suptitle("frequency misfit against each covariate: before (grey), after (blue)", fontsize=9)
    fig.tight_layout()
    data = {"covariates": covs, "mode_numbers": modes, "residual_before_pct": 100 * before,
            "residual_after_pct": 100 * after}
    return figure_json(fig, fig_dir, "explain_residuals_covariates",
                       "What the misfit follows: every mode's misfit against each covariate, before and after",
                       plain(data))


def _form_figure(form: dict[str, Any], fig_dir: Path) -> Figure:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6, 3.4))
    x, y = np.asarray(form["x"], float), np.asarray(form["y"], float)
    ax.plot(x, y, color="tab:blue")
    if form.get("lower") is not None and form.get("upper") is not None:
        ax.fill_between(x, np.asarray(form["lower"], float), np.asarray(form["upper"], float),
                        color="tab:blue", alpha=0.2, lw=0, label="95 % band")
        ax.legend(fontsize=7)
    ax.set_xlabel(form.get("x_label", "x"))
    ax.set_ylabel(form.get("y_label", "factor"))
    ax.set_title(form.get("title", "fitted form of the selected physics"), fontsize=9)
    fig.tight_layout()
    return figure_json(fig, fig_dir, "explain_form", form.get("title", "Fitted form of the selected physics"),
                       plain(form))


def _event_figures(ev: dict[str, Any], fig_dir: Path) -> list[Figure]:
    """Time domain: every event's NRMS before / after against its amplitude (held-out events marked),
    and the strongest event's record at the top sensor with both models' predictions."""
    plt = pyplot()
    figs: list[Figure] = []
    key = next((k for k in ("rms_accel_m_s2", "pga_m_s2") if k in ev), None)
    before, after = np.asarray(ev.get("nrms_before", []), float), np.asarray(ev.get("nrms_after", []), float)
    if key is not None and before.size:
        a = np.asarray(ev[key], float)
        held = np.zeros(a.size, bool)
        held[[int(i) for i in ev.get("held_out", [])]] = True
        fig, ax = plt.subplots(figsize=(6, 3.4))
        ax.plot(a, before, "o", color="0.6", label="nominal model")
        ax.plot(a[~held], after[~held], "o", color="tab:blue", label="with the accepted physics (fitted)")
        ax.plot(a[held], after[held], "s", color="tab:orange", label="with the accepted physics (held out)")
        ax.set_xlabel(key)
        ax.set_ylabel("NRMS of the predicted response, %")
        ax.set_ylim(bottom=0)
        ax.legend(fontsize=7)
        fig.tight_layout()
        figs.append(figure_json(fig, fig_dir, "explain_events_nrms", "Every event's prediction error (NRMS over "
                                "its channels) against its amplitude, before and after", plain(
                                    {key: a, "nrms_before": before, "nrms_after": after, "held_out": held})))
    x = ev.get("example") or {}
    if x.get("measured"):
        y = np.asarray(x["measured"], float)
        t = np.arange(y.size) * float(x["dt"])
        fig, ax = plt.subplots(figsize=(9, 3.2))
        ax.plot(t, y, color="k", lw=0.7, label="measured")
        ax.plot(t, np.asarray(x["before"], float), color="0.6", lw=0.7, label="nominal model")
        if x.get("after"):
            ax.plot(t, np.asarray(x["after"], float), color="tab:blue", lw=0.7, label="with the accepted physics")
        ax.set_xlabel("s")
        ax.set_ylabel(f"{x['channel']}, m/s^2")
        ax.set_title(f"strongest event ({x['window_id']})", fontsize=9)
        ax.legend(fontsize=7, ncol=3)
        fig.tight_layout()
        figs.append(figure_json(fig, fig_dir, "explain_events_record", "The strongest event at the top sensor: "
                                "measured, predicted by the nominal model and with the accepted physics", plain(x)))
    return figs


BUILDER = ExplainSection()
