"""Scoring one explain verdict against its case's truth (the acceptance criteria of docs/explain.md).

Per case: the right top name (the first entry other than ``unmodelled_modes``; a tie that the
verdict reports, ``tied_with``, counts when the truth is among the tied names), its key parameter
against the truth (knee within 1.5 degC, change window within 6 windows, spring / mass / slope /
damper parameter within 25 %), the RMSE of the model's frequencies against the case's noise-free truth at
least halved (damping for ``amplitude_dependent_damping``; the verdict's own RMSE against the noisy
data cannot fall below the identification scatter), the held-out windows improved; for ``unmodelled_modes`` at least
3 of 4 of the out-of-class modes listed; for a clean case no entry other than ``unmodelled_modes``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

KNEE_C, WINDOWS, REL = 1.5, 6, 0.25
BEARING_K = 5.0e9  # the girder's nominal vertical bearing stiffness (shm_ros.core.simulate.scenario)


@dataclass
class Score:
    name: str
    top: str | None
    top_ok: bool
    checks: dict[str, bool] = field(default_factory=dict)
    details: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.top_ok and all(self.checks.values())


def _rel(a: float, b: float) -> bool:
    return abs(a - b) <= REL * abs(b)


def top_entry(v: dict[str, Any]) -> dict[str, Any] | None:
    return next((m for m in v["missing_physics"] if m["name"] != "unmodelled_modes"), None)


def parameter_checks(name: str, top: dict[str, Any], truth: Any, times: np.ndarray) -> dict[str, bool]:
    """The key parameters of the top entry against the case's truth."""
    p, t = top["parameters"], truth.parameters
    out: dict[str, bool] = {}
    if truth.knee_c is not None and "knee_c" in p:
        out["knee"] = abs(p["knee_c"] - truth.knee_c) <= KNEE_C
    if truth.change_index is not None and top.get("change_window") is not None:
        out["time"] = abs(int(top["change_window"]) - int(truth.change_index)) <= WINDOWS
    if name == "temperature_dependent_stiffness":
        if t.get("form") == "bilinear" and "below_per_c" in p:
            out["slope"] = _rel(p["below_per_c"] + p.get("alpha_per_c", 0.0), -t["scale"] * (1 + t["above_ratio"]))
        elif "alpha_per_c" in p:
            out["slope"] = _rel(p["alpha_per_c"], -t["scale"])
    elif name == "amplitude_dependent_stiffness" and "softening_per_accel" in p:
        out["slope"] = _rel(p["softening_per_accel"], t["scale"])
    elif name == "amplitude_dependent_damping" and "damping_per_accel" in p:
        out["slope"] = _rel(p["damping_per_accel"], 1.0 / t["accel_ref_m_s2"])
    elif name == "added_mass" and "mass_fraction" in p:
        out["mass"] = _rel(p["mass_fraction"], t["fraction"])
    elif name == "support_flexibility":
        # the case scales the truth's bearing springs, in series with the soil; the model's support
        # spring stands for both
        kb, ks = BEARING_K, float(t.get("k_soil_n_m", np.inf))

        def eff(factor: float) -> float:
            return 1.0 / (1.0 / (kb * factor) + 1.0 / ks)

        if "ln_step" in p and t.get("mode") == "scour":
            out["spring"] = _rel(float(np.expm1(p["ln_step"])), eff(1 - t["scale"]) / eff(1.0) - 1)
        elif "frost_per_c" in p and t.get("mode") == "frozen":
            out["spring"] = _rel(p["frost_per_c"], eff(1 + t["scale"]) / eff(1.0) - 1)
    elif name == "damper_stiffness":
        # the change of the braces' stiffness in units of the braced story's calibrated stiffness:
        # the calibration absorbs the braces' constant part, so that unit is the story's own
        # stiffness plus the brace's, (1 + k_rel) in the truth's story units
        unit = 1.0 + float(t.get("k_rel", 0.0))
        if "brace_lost" in p and t.get("mode") == "failure":
            out["damper"] = _rel(p["brace_lost"], t["scale"] * t["k_rel"] / unit)
        elif "brace_change_per_c" in p and t.get("mode") == "temperature":
            out["damper"] = _rel(p["brace_change_per_c"], -t["scale"] * t["k_rel"] / unit)
    return out


def truth_misfit(case: Any, series: dict[str, Any], damping: bool = False) -> tuple[float | None, float | None]:
    """RMSE (%) of the model's per-window frequencies (damping ratios) against the case's noise-free
    truth, before and after the accepted effects, each mode's constant offset taken out (the
    model-form offset is not what explain fits). The model's values are the observed ones less the
    verdict's residuals (``explain_series``)."""
    key = "damping" if damping else "residual"
    rb, ra = series.get(f"log_{key}_before"), series.get(f"log_{key}_after")
    truth = case.z_true if damping else case.f_true
    if rb is None or ra is None or truth is None:
        return None, None
    cols = [case.obs.mode_numbers.index(m) for m in series["mode_numbers"]]
    obs = np.log(case.obs.damping if damping else case.obs.frequencies_hz)[:, cols]
    lt = np.log(truth)[:, cols]

    def rmse(res: np.ndarray) -> float:
        e = (obs - np.asarray(res, float)) - lt
        e = e - np.nanmean(e, axis=0)
        return float(100 * np.sqrt(np.nanmean(e ** 2)))

    return rmse(rb), rmse(ra)


def score(verdict: dict[str, Any], case: Any, series: dict[str, Any] | None = None) -> Score:
    truth = case.truth
    name = truth.name
    series = series or {}
    top = top_entry(verdict)
    fit = verdict["fit"]
    if name in ("clean", "unmodelled_modes"):
        listed = {int(m["where"].split()[2]) for m in verdict["missing_physics"] if m["name"] == "unmodelled_modes"}
        s = Score(name, top and top["name"], top is None)
        oop = list(truth.out_of_plane_modes)
        if name == "unmodelled_modes":
            s.checks["listed"] = len(set(oop[:4]) & listed) >= min(3, len(oop[:4]))
        s.details["listed"] = sorted(listed)
        return s
    names = [top["name"], *[lab.split("/")[0] for lab in top.get("tied_with", [])]] if top else []
    s = Score(name, top and top["name"], name in names)
    s.details["tied"] = top.get("tied_with", []) if top else []
    if not s.top_ok or top is None:
        return s
    s.checks.update(parameter_checks(name, top, truth, case.obs.times))
    b, a = truth_misfit(case, series, name == "amplitude_dependent_damping")
    if b is not None and a is not None:  # the model's misfit to the noise-free truth at least halved
        s.checks["halved"] = a <= 0.5 * b
        s.details.update(truth_rmse_before=b, truth_rmse_after=a)
    key = "damping_rmse_pct" if name == "amplitude_dependent_damping" else "frequency_rmse_pct"
    hb, ha = fit["held_out"]["before"].get(key), fit["held_out"]["after"].get(key)
    if hb is not None and ha is not None:
        s.checks["held_out"] = ha < hb
    s.details.update(before=b, after=a, held_before=hb, held_after=ha, parameters=top["parameters"])
    return s
