"""What explain produces: the verdict of docs/interfaces.md §5 as typed dataclasses."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .fit_ratio import FIT_RATIO_LIMIT
from .whiteness import Whiteness


@dataclass
class Mismatch:
    """Where model and data disagree (before any candidate is added)."""

    modes: list[int]  # tracked mode numbers whose misfit is structured (not noise)
    sensors: list[str]
    covariates: dict[str, float]  # correlation of the misfit with each covariate
    summary: str
    details: dict[str, Any] = field(default_factory=dict)  # per-mode tests, change points, patterns


@dataclass
class FitScores:
    frequency_rmse_pct: float | None = None  # None on the time-domain path (events, not modes)
    mac_mean: float | None = None
    damping_rmse_pct: float | None = None  # percentage points of damping ratio
    nrms_pct: float | None = None  # time-domain candidates

    def to_dict(self) -> dict[str, float]:
        d = {"frequency_rmse_pct": self.frequency_rmse_pct, "mac_mean": self.mac_mean,
             "damping_rmse_pct": self.damping_rmse_pct, "nrms_pct": self.nrms_pct}
        return {k: float(v) for k, v in d.items() if v is not None}


@dataclass
class CandidateResult:
    """One candidate fitted to the data, accepted or not."""

    name: str  # vocabulary name (docs/interfaces.md §5)
    label: str  # the candidate's own label, e.g. "temperature_dependent_stiffness/bilinear/deck"
    form: str  # plain words with the fitted values, e.g. "bilinear, knee at -0.5 degC"
    where: str  # region, parameter group or mode list
    parameters: dict[str, float]  # MAP of the candidate's own parameters
    intervals: dict[str, tuple[float, float]]  # 95 % credible interval per parameter
    log_evidence_gain: float  # ln Z(candidate) - ln Z(nominal), primary estimator
    log_evidence_gain_check: float | None  # the same by the second, independent estimator
    log_evidence_gain_err: float  # standard error of the primary estimate
    prior_sensitivity: dict[str, float]  # gain when prior widths are halved / doubled
    time: str | None = None  # ISO 8601, for an effect that starts at a moment
    accepted: bool = False
    reasons: list[str] = field(default_factory=list)  # why accepted / rejected, plain words
    explanation: str = ""  # what the effect is, for an engineer
    fit_after: FitScores | None = None
    held_out_after: FitScores | None = None
    tied_with: list[str] = field(default_factory=list)  # labels the data cannot tell apart from this one
    extra: dict[str, Any] = field(default_factory=dict)  # figures' data (fitted curve, ...)
    # does the effect's functional form fit what it explains? False: structure left in its residual
    # (the form flag, set by the candidate's check or by the whiteness of its residual); None: not judged
    form_fits: bool | None = None
    downgraded_by: str | None = None  # "catch_all" or "whiteness": weakened by what remains; None
    failed: str | None = None  # a named numerical failure of its fit (the reason); None when it ran

    @property
    def confident(self) -> bool:
        """Accepted, its form not seen to fail, not downgraded: a confident name."""
        return self.accepted and self.form_fits is not False and self.downgraded_by is None

    def entry(self) -> dict[str, Any]:
        """The ``missing_physics`` entry of verdict.json."""
        out: dict[str, Any] = {"name": self.name, "form": self.form, "parameters": dict(self.parameters),
                               "log_evidence_gain": float(self.log_evidence_gain), "where": self.where,
                               "label": self.label, "explanation": self.explanation,
                               "intervals": {k: [float(a), float(b)] for k, (a, b) in self.intervals.items()},
                               "form_fits": self.form_fits, "downgraded_by": self.downgraded_by}
        if self.time is not None:
            out["time"] = self.time
        if "change_window" in self.extra:
            out["change_window"] = int(self.extra["change_window"])  # first window after the change
        if self.tied_with:
            out["tied_with"] = list(self.tied_with)
        if "estimated_on" in self.extra:
            out["estimated_on"] = str(self.extra["estimated_on"])
        return out


@dataclass
class Verdict:
    mismatch: Mismatch
    missing_physics: list[CandidateResult]  # accepted, most supported first
    tried: list[CandidateResult]  # every candidate fitted (accepted or not), for the report's table
    fit_before: FitScores
    fit_after: FitScores
    held_out_before: FitScores
    held_out_after: FitScores
    unexplained: dict[str, Any] | None = None  # the catch-all beat every named candidate: where / when
    # identification scatter (window to window), the floor below which no model fits: frequency in %,
    # damping ratio in percentage points
    scatter: dict[str, float | None] = field(default_factory=dict)
    threshold: dict[str, Any] = field(default_factory=dict)  # the acceptance threshold and its calibration
    notes: list[str] = field(default_factory=list)
    figures: dict[str, Any] = field(default_factory=dict)  # numbers behind the report's figures
    whiteness: Whiteness | None = None  # per mode: is the misfit before / after noise? (modal tables)
    status: str = "ok"  # "ok", or "no_windows": nothing to analyse (exit code 3)
    # the fit ratio after the accepted effects (docs/interfaces.md §5) and its parts per path / mode
    fit_ratio: float | None = None
    fit_ratio_details: dict[str, Any] = field(default_factory=dict)

    @property
    def model_fits(self) -> bool | None:
        """False when the fit ratio after the accepted effects reaches :data:`FIT_RATIO_LIMIT`; None
        when it could not be computed (no windows)."""
        if self.fit_ratio is None or not np.isfinite(self.fit_ratio):
            return None
        return bool(self.fit_ratio < FIT_RATIO_LIMIT)

    @classmethod
    def no_windows(cls, reason: str) -> Verdict:
        """The verdict of an input without a single analysis window (``status: no_windows``)."""
        empty = FitScores()
        return cls(mismatch=Mismatch(modes=[], sensors=[], covariates={}, summary=f"no analysis window: {reason}"),
                   missing_physics=[], tried=[], fit_before=empty, fit_after=empty, held_out_before=empty,
                   held_out_after=empty, notes=[reason], status="no_windows")

    def to_dict(self) -> dict[str, Any]:
        m = self.mismatch
        out: dict[str, Any] = {
            "status": self.status, "model_fits": self.model_fits,
            "fit_ratio": None if self.fit_ratio is None or not np.isfinite(self.fit_ratio) else float(self.fit_ratio),
            "mismatch": {"modes": list(m.modes), "sensors": list(m.sensors),
                         "covariates": {k: float(v) for k, v in m.covariates.items()}, "summary": m.summary},
            "missing_physics": [c.entry() for c in self.missing_physics],
            "fit": {"before": self.fit_before.to_dict(), "after": self.fit_after.to_dict(),
                    "held_out": {"before": self.held_out_before.to_dict(),
                                 "after": self.held_out_after.to_dict()},
                    "scatter": {k: v for k, v in self.scatter.items() if v is not None}},
            "candidates": [{**c.entry(), "accepted": c.accepted, "reasons": list(c.reasons),
                            "log_evidence_gain_check": c.log_evidence_gain_check,
                            "log_evidence_gain_err": c.log_evidence_gain_err,
                            "log_evidence_gain_check_err": c.extra.get("check_err"),
                            "check_agrees": c.extra.get("check_agrees"),
                            "prior_sensitivity": dict(c.prior_sensitivity), "failed": c.failed,
                            **{k: float(c.extra[k]) for k in ("relative_support", "shape_log_likelihood")
                               if k in c.extra}} for c in self.tried],
            "threshold": dict(self.threshold),
            "notes": list(self.notes),
        }
        if self.fit_ratio_details:
            out["fit"]["fit_ratio"] = dict(self.fit_ratio_details)
        out["unexplained_structure"] = None
        if self.whiteness is not None:
            out["fit"]["residual_whiteness"] = self.whiteness.to_dict()
        if self.unexplained is not None:
            out["unexplained_structure"] = dict(self.unexplained)
        return out


@dataclass
class Baseline:
    """The calibrated nominal model against the data, per window and tracked mode.

    ``log_residual[w, k] = ln f_obs - ln f_model`` for tracked mode ``mode_numbers[k]`` paired with
    model mode ``model_index[k]`` (modes that pair with none are in ``unpaired`` and have no column).
    """

    mode_numbers: list[int]
    model_index: list[int]
    log_residual: np.ndarray  # (W, K)
    f_model: np.ndarray  # (K,) baseline model frequencies, Hz
    sensitivities: dict[str, np.ndarray]  # group -> (K,) d ln f / d ln(group factor) at the baseline
    theta: dict[str, float]  # the calibrated nominal parameters
    unpaired: list[dict[str, Any]] = field(default_factory=list)  # as posterior.json unmodelled_modes
    train: np.ndarray | None = None  # (W,) bool: windows used to fit; the others are held out


@dataclass
class Proposal:
    """A candidate that locate asks the engine to fit: registry label, group, and why."""

    candidate: str  # CANDIDATES label
    group: str  # parameter group (groups.py names: EI, EI:k, bearings, bearings_rot, mass, mass:k, damper)
    reason: str  # plain words: what in the residuals suggests it
    hints: dict[str, Any] = field(default_factory=dict)  # e.g. {"knee_c": -0.4}, {"change_index": 512}
