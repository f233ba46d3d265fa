"""The report's first page: what was measured, what changed, what the model is missing, how sure.

Plain sentences with units, built from whatever stages have run (a sentence per stage; stages that
did not run say nothing). The owner of a structure reads this and nothing else.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from shm_ros.report.inputs import ReportInputs


def summary_sentences(inputs: ReportInputs) -> list[str]:
    out: list[str] = []
    for part in (_measured, _modes, _changes, _model, _robust, _predicted, _missing):
        try:
            with warnings.catch_warnings():  # modes never found are NaN columns: no number, no warning
                warnings.simplefilter("ignore", RuntimeWarning)
                text = part(inputs)
        except (KeyError, ValueError, TypeError, IndexError):  # a summary must never stop a report
            text = None
        if text:
            out.append(text)
    return out


def _measured(x: ReportInputs) -> str | None:
    if x.ingest is None or not x.ingest.windows:
        return None
    w = x.ingest.windows
    t0, t1 = min(v.start_ns for v in w), max(v.end_ns for v in w)
    span = (t1 - t0) / 1e9
    dur = f"{span / 86400:.1f} days" if span > 2 * 86400 else f"{span / 3600:.1f} hours" if span > 7200 \
        else f"{span / 60:.0f} minutes"
    channels = sorted({c for v in w for c in v.channels})
    rates = sorted({round(v.sample_rate_hz) for v in w if math.isfinite(v.sample_rate_hz)})
    temps = [v.temperature_c for v in w if v.temperature_c is not None]
    quakes = sum(v.is_event and v.event_kind == "earthquake" for v in w)
    loud = sum(v.is_event and v.event_kind != "earthquake" for v in w)
    s = (f"Measured: {len(w)} analysis windows over {dur}, {len(channels)} channels at "
         f"{'/'.join(str(r) for r in rates)} Hz")
    if temps:
        s += f", air temperature {min(temps):.1f} to {max(temps):.1f} °C"
    if quakes:
        s += f", {quakes} earthquake{'s' if quakes > 1 else ''} (at the ground/input sensor)"
    if loud:
        s += f", {loud} high-amplitude window{'s' if loud > 1 else ''} (traffic, wind or works; no earthquake)"
    bad = sum(1 for v in w for st in v.status if st != "ok")
    return s + (f"; {bad} channel-windows were flagged (dead, clipped, noisy or dropped)." if bad else ".")


def _modes(x: ReportInputs) -> str | None:
    if x.tracking is None:
        return None
    obs = x.tracking.observations
    f = np.nanmean(obs.frequencies_hz, axis=0)
    found = np.mean(np.isfinite(obs.frequencies_hz), axis=0)
    parts = [f"{fi:.2f} Hz" for fi in f if np.isfinite(fi)]
    return (f"Vibration modes: {len(parts)} modes tracked through the campaign ({', '.join(parts)}), found in "
            f"{100 * float(np.min(found)):.0f}-{100 * float(np.max(found)):.0f} % of the windows.")


def _changes(x: ReportInputs) -> str | None:
    if x.tracking is None:
        return None
    t = x.tracking
    obs = t.observations
    f = obs.frequencies_hz
    lo, hi = np.nanpercentile(f, 2, axis=0), np.nanpercentile(f, 98, axis=0)
    swing = 100 * float(np.nanmax((hi - lo) / np.nanmean(f, axis=0)))
    s = f"What changed: the frequencies varied by up to {swing:.1f} % over the campaign"
    if t.environment:
        s += " (mostly with the environment, which the tracker models)"
    n_alarm = int(np.sum(t.novelty_alarm))
    if n_alarm:
        s += (f"; {n_alarm} windows in {len(t.episodes) or 1} episode(s) were abnormal even after removing the "
              "environment's effect")
    else:
        s += "; no window was abnormal once the environment's effect was removed"
    return s + "."


def _model(x: ReportInputs) -> str | None:
    p = x.posterior
    if p is None:
        return None
    parts = [f"{n} {s.mean:.3f} (95 % interval {s.ci95[0]:.3f}-{s.ci95[1]:.3f})" for n, s in p.parameters.items()]
    fit = p.fit.get("frequency_rmse_pct") if isinstance(p.fit, dict) else None
    s = "Calibrated model: " + "; ".join(parts)
    if fit is not None:
        s += f"; it reproduces the measured frequencies to {float(fit):.2f} % RMS"
    return s + "."


def _robust(x: ReportInputs) -> str | None:
    study = (x.papers or {}).get("table1")
    if not study or not study.get("rows"):
        return None
    rows = study["rows"]
    spans = []
    for name in rows[0]["parameters"]:
        v = [float(r["parameters"][name]) for r in rows]
        spans.append(f"{name} {min(v):.3f}-{max(v):.3f}")
    rmse = [100 * float(e) for r in rows for e in r["rmse"] if e is not None]
    return (f"How much the calibration depends on its assumptions: over the {len(rows)} prior families and "
            f"frequency/shape weightings of the bridge paper's Table 1, the calibrated values ranged {', '.join(spans)}"
            f", and the per-mode frequency errors {min(rmse):.1f}-{max(rmse):.1f} % RMS.")


def _predicted(x: ReportInputs) -> str | None:
    p = x.prediction
    if p is None or not getattr(p, "payload", None):
        return None
    sm = p.payload.get("summary", {})
    if sm.get("nrms_pct_median") is None:
        return None
    s = (f"Prediction: fed the measured ground motion of {sm.get('n_events', '?')} event(s), the calibrated model "
         f"reproduces the measured floor accelerations with a median error (NRMS) of {sm['nrms_pct_median']:.1f} %")
    if sm.get("nrms_pct_nominal_median") is not None:
        s += f" (the nominal model: {sm['nrms_pct_nominal_median']:.1f} %)"
    s += "."
    risky = []
    for ev in p.payload.get("events", []):
        for st in (ev.get("risk") or {}).get("stories", []):
            top = max(st.get("exceedance", []), key=lambda e: e["limit"] if e["probability"] >= 0.5 else -1,
                      default=None)
            if top is not None and top["probability"] >= 0.5:
                risky.append((ev["window_id"], st["story"], top["limit"], top["probability"]))
    if risky:
        w, k, lim, prob = max(risky, key=lambda r: (r[2], r[3]))
        s += (f" In {len({r[0] for r in risky})} event(s) a story's drift ratio more likely than not exceeded a "
              f"limit (the highest: {lim:g} at story {k} of {w}, probability {prob:.2f}).")
    outside = sm.get("events_outside_calibration") or []
    if outside:
        s += (f" {len(outside)} event(s) lay outside what the calibration saw (stronger shaking or drift beyond "
              f"the elastic range): their predictions are extrapolations.")
    return s


def _missing(x: ReportInputs) -> str | None:
    if x.explain is None:
        return None
    v = x.explain.verdict
    found = [m for m in v.get("missing_physics", []) if m.get("name") != "unmodelled_modes"]
    unmod = [m for m in v.get("missing_physics", []) if m.get("name") == "unmodelled_modes"]
    if v.get("status", "ok") != "ok":
        return f"What the model is missing: not analysed ({v['status']})."
    if not found and v.get("model_fits"):
        s = "What the model is missing: nothing that the recordings can show beyond their scatter"
    elif not found:
        s = (f"What the model is missing: nothing named, yet the model does not fit within the scatter "
             f"(fit ratio {v.get('fit_ratio') if v.get('fit_ratio') is not None else 'unknown'})")
    else:
        m = found[0]
        when = f" from {m['time']}" if m.get("time") else ""
        s = (f"What the model is missing: {m['name'].replace('_', ' ')}"
             f"{' at ' + str(m['where']) if m.get('where') else ''}{when} — {m.get('form', '')}")
        f = v.get("fit", {})
        b, a = f.get("before", {}).get("frequency_rmse_pct"), f.get("after", {}).get("frequency_rmse_pct")
        if b is not None and a is not None:
            s += f"; adding it brings the frequency misfit from {b:.2f} % to {a:.2f} % RMS"
        if len(found) > 1:
            s += f" (and {len(found) - 1} more effect(s), see the explanation)"
        if v.get("model_fits") is False:
            s += f"; even so the model does not fit within the scatter (fit ratio {float(v['fit_ratio']):.1f})"
    if unmod:
        s += (f"; the recordings also hold modes the model's class cannot have ({unmod[0].get('where', '')}): "
              "a richer model (e.g. 3-D) would be needed for them")
    return s + "."
