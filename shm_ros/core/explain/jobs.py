"""A candidate bound to the data (its gain on the training windows), the same on top of effects
already accepted, and the :class:`~.types.CandidateResult` of a fit."""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime, timezone

import numpy as np

from .candidates.base import Candidate, Modification, ParamSpec
from .config import ExplainConfig
from .fit import Box, FitResult, fit
from .form_check import form_gain
from .joint import joint_modification
from .likelihood import CandidateLikelihood
from .scoring import damping_scores, judged_windows, scores
from .surrogate import Surrogate
from .types import CandidateResult

Span = tuple[float, float] | None  # seconds since the first window within which an effect starts


def iso_time(epoch: float, t: float | None) -> str | None:
    if t is None:
        return None
    return datetime.fromtimestamp(epoch + t, tz=timezone.utc).isoformat().replace("+00:00", "Z")


class Job:
    """A candidate bound to the data: its gain function on the training windows."""

    def __init__(self, cand: Candidate, sur: Surrogate, lik: CandidateLikelihood, train: np.ndarray):
        self.cand, self.sur, self.lik, self.train = cand, sur, lik, train
        self.specs: list[ParamSpec] = cand.params()

    def deltas(self, theta: np.ndarray, windows: np.ndarray | None = None):
        mod = self.cand.modify(np.atleast_2d(theta))
        sel = slice(None) if windows is None else windows
        d = None
        if mod.groups:
            d = self.sur.delta(Modification({g: x[:, sel] for g, x in mod.groups.items()}))
        dd = None if mod.damping is None else np.log(np.maximum(mod.damping[:, sel], 1e-9))[..., None]
        return d, dd

    def gain(self, theta: np.ndarray) -> np.ndarray:
        d, dd = self.deltas(theta, self.train)
        return self.lik.gain(d, dd)

    def reference_deltas(self):
        """The changes of the model the candidate is compared with (the nominal model: none)."""
        return None, None


class OnTopJob(Job):
    """An effect on top of accepted ones, evaluated cheaply: the accepted effects' change of the
    log-frequencies (exact, computed once) plus the new effect's own change (the surrogate of its
    groups alone) plus a cross term, the exact joint change less those two, computed at one point
    (``anchor``: the new effect's MAP of a first pass) and held fixed. Where several groups change
    with continuous covariates the joint surrogate needs a small eigenproblem per window and draw;
    this costs one. The joint model at the MAP is exact by construction; away from it the error is
    second order in the parameters' deviation (the candidates' surrogate check reports it)."""

    def __init__(self, cand: OnTop, sur: Surrogate, lik: CandidateLikelihood, train: np.ndarray):
        super().__init__(cand, sur, lik, train)
        self.new_cand: Candidate = cand.new
        fixed = Modification({}, None)
        for c, th in cand.fixed:
            f = c.modify(th[None])
            for g, x in f.groups.items():
                fixed.groups[g] = fixed.groups[g] * x if g in fixed.groups else np.array(x, dtype=float)
            if f.damping is not None:
                fixed.damping = f.damping if fixed.damping is None else fixed.damping * f.damping
        self.fixed_mod = fixed
        self.d_fixed = sur.delta(fixed)[0] if fixed.groups else None  # (W, K)
        self.cross: np.ndarray | None = None

    def anchor(self, theta: np.ndarray) -> None:
        """Exact joint change at ``theta`` less the two parts: the cross term."""
        self.cross = None
        joint, _ = Job.deltas(self, theta)
        parts, _ = self.deltas(theta)
        self.cross = None if joint is None or parts is None else (joint - parts)[0]

    def reference_deltas(self):
        """The effects it is fitted on top of, alone (the model it is compared with)."""
        dd = None if self.fixed_mod.damping is None else np.log(np.maximum(self.fixed_mod.damping, 1e-9))[..., None]
        return None if self.d_fixed is None else self.d_fixed[None], dd

    def deltas(self, theta: np.ndarray, windows: np.ndarray | None = None):
        sel = slice(None) if windows is None else windows
        new = self.new_cand.modify(np.atleast_2d(theta))
        d = None
        if new.groups:
            d = self.sur.delta(Modification({g: x[:, sel] for g, x in new.groups.items()}))
        if self.d_fixed is not None:
            base = self.d_fixed[sel][None]
            d = base if d is None else d + base
        if d is not None and self.cross is not None:
            d = d + self.cross[sel][None]
        damping = new.damping
        if self.fixed_mod.damping is not None:
            damping = self.fixed_mod.damping if damping is None else damping * self.fixed_mod.damping
        dd = None if damping is None else np.log(np.maximum(damping[:, sel], 1e-9))[..., None]
        if d is not None and d.shape[0] == 1 and np.atleast_2d(theta).shape[0] > 1:
            d = np.repeat(d, np.atleast_2d(theta).shape[0], axis=0)
        return d, dd


class OnTop(Candidate):
    """A candidate fitted on top of effects already accepted, those held at their MAP (the second
    round): its evidence gain over them is ln Z(new | accepted) - ln L(accepted at their MAP).
    Holding the accepted effects fixed is the approximation that keeps this as cheap as a first-round
    fit; they are determined far better than the new, smaller effect."""

    def __init__(self, new: Candidate, fixed: list[tuple[Candidate, np.ndarray]]):
        super().__init__(new.group, new.context)
        self.new, self.fixed = new, list(fixed)  # a copy: the caller appends to its list later
        self.vocabulary = new.vocabulary  # type: ignore[misc]  # the instance speaks for the new effect
        self.name = new.name  # type: ignore[misc]  # a ClassVar elsewhere: this instance stands for `new`
        self.explanation = new.explanation  # type: ignore[misc]  # likewise

    @property
    def label(self) -> str:
        return self.new.label

    def params(self) -> list[ParamSpec]:
        return self.new.params()

    def modify(self, theta: np.ndarray):
        return joint_modification([(self.new, theta), *((c, th[None]) for c, th in self.fixed)])

    def form(self, theta: np.ndarray) -> str:
        return self.new.form(theta)

    def time(self, theta: np.ndarray) -> float | None:
        return self.new.time(theta)

    def key_parameter(self) -> str:
        return self.new.key_parameter()

    def look_elsewhere(self) -> float:
        return self.new.look_elsewhere()


def result(job: Job, fr: FitResult, r_all: np.ndarray, train: np.ndarray, epoch: float,
           z_all: np.ndarray | None = None, placed: Sequence[tuple[str, Span]] = ()) -> CandidateResult:
    """The fit's result: parameters, evidence gain and scores. ``placed``: (label, time span) of the
    effects ``job`` is fitted on top of; the held-out windows the training windows cannot fix for
    its own start or for theirs are left out of its held-out check (:func:`judged_on`)."""
    c = job.cand
    d_all, _ = job.deltas(fr.theta_map)
    delta = None if d_all is None else d_all[0]
    fit_after, held_after = scores(r_all, delta, train)
    res_acts = "frequency" if delta is not None else "damping"
    if z_all is not None:
        _, dd = job.deltas(fr.theta_map)
        fit_after.damping_rmse_pct, held_after.damping_rmse_pct = damping_scores(
            z_all, None if dd is None else dd[0], train)
    key = c.key_parameter()
    res = CandidateResult(
        name=c.vocabulary, label=c.label, form=c.form(fr.theta_map), where=c.group,
        parameters=c.describe(fr.theta_map), intervals=fr.intervals,
        log_evidence_gain=float(fr.evidence.log_z) - c.look_elsewhere(),
        log_evidence_gain_check=None if fr.check is None else fr.check - c.look_elsewhere(),
        log_evidence_gain_err=float(fr.evidence.err), prior_sensitivity=dict(fr.prior_sensitivity),
        time=iso_time(epoch, c.time(fr.theta_map)), explanation=c.explanation, fit_after=fit_after,
        held_out_after=held_after)
    if delta is not None:
        res.extra["delta"] = delta  # (W, K) change of ln f at the MAP: ties (select.decide)
        res.extra["fitted_windows"] = train
        mod = c.modify(np.atleast_2d(fr.theta_map))
        if mod.groups:  # the form flag's evidence (form_check): smooth functions of the effect's factor
            x = np.asarray(next(iter(mod.groups.values()))[0], float)
            res.extra["form_gain"] = form_gain(x[train], (r_all - delta)[train], job.lik.noise_guess)
    if delta is None and z_all is not None:  # a damping candidate: the same form check on ln zeta
        _form_on_damping(res, job, fr.theta_map, z_all, train)
    if c.look_elsewhere():
        res.extra["look_elsewhere_nats"] = c.look_elsewhere()
    res.extra.update({"key_parameter": key, "gain_at_map": fr.gain_map, "acts_on": res_acts, "evaluations": fr.n_eval,
                      "check_method": fr.check_method, "check_err": fr.check_err})
    t0 = c.time(fr.theta_map)
    if t0 is not None:
        res.extra["change_window"] = int(np.searchsorted(job.cand.context.times_s, t0))
    judged, starts = judged_on(c.context.times_s, train, [("", c.time_span(fr.theta_map, fr.intervals)), *placed])
    if judged.sum() < (~train).sum():
        res.extra["held_out_check"] = {**held_out_check(job, fr.theta_map, r_all, z_all, train, judged),
                                       "starts": starts}
    return res


def judged_on(times_s: np.ndarray, train: np.ndarray, spans: Sequence[tuple[str, Span]]) -> tuple[np.ndarray, str]:
    """The held-out windows that judge a candidate (:func:`.scoring.judged_windows` for each start),
    and whose starts leave windows out (``spans``: (label, span); label "" for the candidate's own).
    On top of an accepted change that the training windows place only within a held-out block, the
    reference model's prediction of that block is a guess as much as the candidate's own start
    would be: with it misplaced, an effect the reference lacks can cancel part of its misfit there
    (a knee's cold spell in the block of a step's start), which judges the guess, not the candidate."""
    judged, whose = ~np.asarray(train, bool), []
    for label, span in spans:
        j = judged & judged_windows(times_s, train, span)
        if (j != judged).any():
            whose.append(f"the start of {label}" if label else "its start")
        judged = j
    return judged, " and ".join(whose)


def held_out_check(job: Job, theta: np.ndarray, r_all: np.ndarray, z_all: np.ndarray | None, train: np.ndarray,
                   judged: np.ndarray) -> dict:
    """The held-out scores with the candidate (``after``) and with the model it is compared with
    (``before``: the nominal model, or the effects it is fitted on top of) on the ``judged`` held-out
    windows alone (:func:`.scoring.judged_windows`), how many of the held-out windows those are, and
    the first and last window left out."""
    out: dict = {}
    for who, (d, dd) in (("after", job.deltas(theta)), ("before", job.reference_deltas())):
        _, s = scores(r_all, None if d is None else d[0], train, judged)
        if z_all is not None:
            _, s.damping_rmse_pct = damping_scores(z_all, None if dd is None else dd[0], train, judged)
        out[who] = s
    left = np.flatnonzero(~train & ~judged)
    return {**out, "windows": int(judged.sum()), "of": int((~train).sum()), "left_out": (int(left[0]), int(left[-1]))}


def _form_on_damping(res: CandidateResult, job: Job, theta: np.ndarray, z_all: np.ndarray, train: np.ndarray) -> None:
    """The form flag's evidence of a damping candidate (form_check): smooth functions of its damping
    factor on the log-damping misfit it leaves (damping scatter from the configuration's default)."""
    mod = job.cand.modify(np.atleast_2d(theta))
    if mod.damping is None:
        return
    _, dd = job.deltas(theta)
    rd = np.log(np.where(z_all > 0, z_all, np.nan))
    after = rd if dd is None else rd - np.broadcast_to(dd[0], rd.shape)
    x = np.asarray(mod.damping[0], float)
    res.extra["form_gain"] = form_gain(x[train], after[train], ExplainConfig().damping_noise_guess)


def fit_on_top(cand: Candidate, fixed: list[tuple[Candidate, np.ndarray]], sur, lik, train, seed: int,
               config: ExplainConfig, start: dict[str, float] | None = None):
    """``cand`` fitted on top of the ``fixed`` effects (held at their values): a first fit, the cross
    term anchored at its MAP, then the final fit (one fit when nothing is fixed). ``start`` (values by
    parameter name, e.g. an earlier fit's MAP) is one more starting point of the MAP search. Returns
    the job and the final fit."""
    job = OnTopJob(OnTop(cand, fixed), sur, lik, train)
    hint = None
    if start is not None and all(s.name in start for s in job.specs):
        hint = np.clip(Box(job.specs).to_unit(np.array([[start[s.name] for s in job.specs]]))[0], 0.0, 1.0)
    fr = fit(job.gain, job.specs, seed=seed, n_is=config.n_importance, sensitivity=False, hint_u=hint)
    if fixed:
        job.anchor(fr.theta_map)
        fr = fit(job.gain, job.specs, seed=seed, n_is=config.n_importance, sensitivity=False,
                 hint_u=Box(job.specs).to_unit(np.atleast_2d(fr.theta_map))[0])
    return job, fr

