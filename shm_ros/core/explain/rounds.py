"""More than one effect: the second round (other candidates fitted on top of the accepted effect and
accepted by the same rules) and the accepted effects' final estimates on every window."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from shm_ros.core.observations import ModalObservations
from shm_ros.errors import NumericalFailure

from .candidates.base import Candidate
from .config import ExplainConfig
from .failures import failed_result, numerical
from .fit import Box, FitResult, evidence_check
from .jobs import Job, OnTop, OnTopJob, Span, fit_on_top, iso_time, result
from .joint import joint_refine
from .likelihood import CandidateLikelihood
from .shapes import shape_terms_of
from .surrogate import Surrogate
from .types import CandidateResult, FitScores

MAX_EFFECTS = 2  # effects reported together (each more costs a round of fits on top of the others)
POOL = 4  # candidates refitted on top per round: the most supported ones alone
BACKFIT_SETTLED = 0.01  # a backfitting pass that moves no parameter by more than this share of its range


def more_effects(accepted, tried, jobs, proposals, context, sur, lik, train, r_all, epoch, threshold, config,
                 say, z_all=None, obs: ModalObservations | None = None, kept: list[int] | None = None,
                 ) -> tuple[list[CandidateResult], FitScores, FitScores, tuple | None, list]:
    """Greedy forward selection: other candidates are refitted on top of the effects accepted so far
    (held at their MAP); the best one is accepted when its gain over them clears the same
    ``threshold``, it improves the held-out windows further (those the training windows fix for its
    start and for the accepted effects' starts) and its key parameter excludes the null;
    repeated up to ``MAX_EFFECTS`` effects, with the ``POOL`` candidates most supported alone. Every
    refit joins ``tried`` (the report's table of candidates), accepted or not. Candidates tied with an
    accepted one, or of the same name and group, are not tried again."""
    best = accepted[0]
    fixed = [(jobs[best.label][0].cand, jobs[best.label][1].theta_map)]
    placed = [_placed(best.label, jobs[best.label][0].cand, jobs[best.label][1])]
    base_gain = float(jobs[best.label][1].gain_map)
    done = {best.label, *best.tied_with}
    fit_after = best.fit_after or FitScores(float("nan"))
    held_after = best.held_out_after or FitScores(float("nan"))
    out: list[CandidateResult] = []
    last = None
    # every candidate tried alone, whatever its gain then: an effect may only show once a larger one
    # is accounted for; other physics first (variations of the accepted effect, e.g. the same knee on
    # another group, mostly explain the misfit it already explains and would fill the pool)
    pool = sorted((c for c in tried if c.label not in done),
                  key=lambda c: (c.name == best.name, -c.log_evidence_gain))[:POOL]
    by_label = {p.candidate + "/" + p.group: p for p in proposals}
    for _ in range(MAX_EFFECTS - 1):
        results = []
        for i, c in enumerate(pool):
            job0 = jobs[c.label][0]
            say(f"fit {c.label} on top of {len(fixed)} effect(s)", 0.9)
            try:
                with numerical(f"{c.label} on top of {len(fixed)} effect(s)"):
                    job, fr = fit_on_top(job0.cand, fixed, sur, lik, train, config.seed + 100 + i, config)
                    res = result(job, fr, r_all, train, epoch, z_all, placed)
            except NumericalFailure as exc:  # named numerical failures only: this refit failed
                tried.append(failed_result(c.name, c.label, c.where, exc, c.explanation))
                continue
            res.log_evidence_gain = float(fr.evidence.log_z - base_gain - job.cand.look_elsewhere())
            res.extra.update({"on_top_of": [f[0].label for f in fixed], "gain_over_nominal": float(fr.evidence.log_z)})
            results.append((res, job, fr))
        results = _set_aside_same_course(results, fixed, best, tried, threshold)
        if not results:
            break
        results.sort(key=lambda t: -t[0].log_evidence_gain)
        # refits the frequencies cannot tell apart (a loss in either mirror span): the shapes choose
        level = [t for t in results if results[0][0].log_evidence_gain - t[0].log_evidence_gain <= config.tie_nats]
        ll = shape_terms(level, sur, obs, kept, train) if len(level) > 1 and obs is not None and kept else None
        if ll is not None:
            top = max(ll.values())
            for r, _, _ in level:
                r.extra["shape_log_likelihood"] = ll[r.label] - top
            results.sort(key=lambda t: -(t[0].log_evidence_gain + t[0].extra.get("shape_log_likelihood", 0.0)))
        for other, _, _ in results[1:]:
            other.reasons = [f"not the best on top of {', '.join(other.extra['on_top_of'])}: evidence gain "
                             f"{other.log_evidence_gain:.1f} nats vs {results[0][0].log_evidence_gain:.1f}"
                             + (f", shapes {other.extra['shape_log_likelihood']:+.1f} nats against it"
                                if "shape_log_likelihood" in other.extra else "")]
            tried.append(other)
        res, job, fr = results[0]
        key = job.cand.key_parameter()
        null = next(sp.null for sp in job.specs if sp.name == key)
        from .select import held_out_pair, null_excluded

        metric, held, ref, where = held_out_pair(res, held_after)
        ok = res.log_evidence_gain > threshold and held < ref and null_excluded(res, key, null)
        res.reasons = [f"{'passed' if res.log_evidence_gain > threshold else 'failed'}: evidence gain "
                       f"{res.log_evidence_gain:.1f} nats on top of {', '.join(res.extra['on_top_of'])} vs "
                       f"threshold {threshold:.1f}",
                       f"{'passed' if held < ref else 'failed'}: held-out {metric} {held:.3f} vs {ref:.3f} "
                       "without it" + where]
        if not ok:
            tried.append(res)
            break
        res.accepted = True
        if config.nested_check:  # the second estimator, of the gain over nominal, less the same base
            chk, err, method = evidence_check(job.gain, Box(job.specs), config.n_live, config.seed + 200, fr.theta_map)
            res.log_evidence_gain_check = float(chk - (res.extra["gain_over_nominal"] - res.log_evidence_gain))
            tol = max(0.5, 3.0 * math.hypot(res.log_evidence_gain_err, err))
            res.extra.update({"check_method": method, "check_err": err,
                              "check_agrees": bool(abs(res.log_evidence_gain_check - res.log_evidence_gain) <= tol)})
        res.extra["proposal_reason"] = getattr(by_label.get(res.label.split("/", 1)[1] if "/" in res.label else ""),
                                               "reason", "")
        out.append(res)
        tried.append(res)
        fixed.append((job.new_cand, fr.theta_map))
        placed.append(_placed(res.label, job.new_cand, fr))
        last = (job, fr.theta_map)
        base_gain = float(fr.gain_map)
        fit_after, held_after = res.fit_after or fit_after, res.held_out_after or held_after
        same = {(c.name, c.where) for c in [best, *out]}
        pool = [c for c in pool if c.label != res.label and (c.name, c.where) not in same]
    return out, fit_after, held_after, last, fixed


def _placed(label: str, cand: Candidate, fr: FitResult) -> tuple[str, Span]:
    """An accepted effect's label and the span its start is placed in (None: it does not start at a
    moment): the held-out windows the training windows cannot fix for it are left out of the
    held-out check of every candidate fitted on top of it, as they are of its own
    (:func:`.jobs.judged_on`)."""
    return label, cand.time_span(fr.theta_map, fr.intervals)


SAME_COURSE = 0.9  # |correlation| of two effects' courses in time above which they are one


def time_course(cand: Candidate, theta: np.ndarray) -> np.ndarray | None:
    """(W,) the candidate's change per window at ``theta`` (its first group's factor, else its
    damping), or None when it does not change over the windows."""
    m = cand.modify(np.atleast_2d(theta))
    for arr in [*m.groups.values(), m.damping, m.added_damping]:
        if arr is not None:
            x = np.asarray(arr, float)[0]
            return x if np.ptp(x) > 0 else None
    return None


def _same_course(fixed: list[tuple[Candidate, np.ndarray]], cand: Candidate, theta: np.ndarray
                 ) -> tuple[str, float] | None:
    """(label, correlation) of the first accepted effect whose course in time ``cand`` follows."""
    x = time_course(cand, theta)
    if x is None:
        return None
    for c, th in fixed:
        y = time_course(c, th)
        if y is not None:
            r = float(np.corrcoef(x, y)[0, 1])
            if abs(r) >= SAME_COURSE:
                return c.label, r
    return None


def _set_aside_same_course(results: list, fixed: list[tuple[Candidate, np.ndarray]], best: CandidateResult,
                           tried: list[CandidateResult], threshold: float) -> list:
    """``results`` (refits on top: result, job, fit) without those that follow an accepted effect's
    course in time (a knee on the mirror span of a knee): they cannot be told from that effect moving
    the modes in other proportions than the model says (model-form error), so they join ``tried``
    with that reason and, when they clear the threshold, are noted on ``best``, never a second effect."""
    kept = []
    for t in results:
        same = _same_course(fixed, t[1].new_cand, t[2].theta_map)
        if same is None:
            kept.append(t)
            continue
        lab, corr = same
        res = t[0]
        res.reasons = [f"not a second effect on top of {', '.join(res.extra['on_top_of'])} "
                       f"({res.log_evidence_gain:+.1f} nats): it follows the course in time of {lab} "
                       f"(correlation {corr:+.2f}), and the frequencies cannot tell it from that effect "
                       "acting on the modes in other proportions than the model's"]
        tried.append(res)
        if res.log_evidence_gain > threshold:
            best.reasons.append(f"note: {res.label} on top of it, with the same course in time, gains "
                                f"{res.log_evidence_gain:.1f} nats: the effect may also act on {res.where}, "
                                "or move the modes in other proportions than the model's")
    return kept


def placed_in_span(cand: Candidate, theta: np.ndarray | None, others: list[tuple[Candidate, np.ndarray]], sur,
                   lik_all: CandidateLikelihood) -> Candidate:
    """``cand`` starting at the window of locate's ``change_span`` that fits every window best at
    ``theta``, for a candidate that starts at the hinted window without a time parameter (a mass, a
    damper's loss, a support's step). A change inside a held-out block is placed by the training
    windows only to that block, and locate hints its first window: on every window a start some
    windows early is misfit there, which a drifting misfit (scored by its jumps) charges like the
    whole change. Others are returned as they are."""
    h = cand.context.hints
    if theta is None or "change_index" not in h or "change_span" not in h or any(s.moment for s in cand.params()):
        return cand
    a, b = (int(x) for x in h["change_span"])
    every = np.ones(len(lik_all.freq.r), dtype=bool)
    best, best_gain = cand, -math.inf
    for i in range(max(a, 1), min(b, len(every) - 1) + 1):
        moved = type(cand)(cand.group, dataclasses.replace(cand.context, hints={**h, "change_index": i}))
        gain = float(OnTopJob(OnTop(moved, others), sur, lik_all, every).gain(np.atleast_2d(theta))[0])
        if gain > best_gain:
            best, best_gain = moved, gain
    return best


def _moved(cand: Candidate, before: np.ndarray, after: np.ndarray) -> float:
    """Largest change of a parameter between two fits, as a fraction of its prior range."""
    box = Box(cand.params())
    return float(np.max(np.abs(box.to_unit(np.atleast_2d(after)) - box.to_unit(np.atleast_2d(before)))))


def final_estimates(chain: list[CandidateResult], fixed: list[tuple[Candidate, np.ndarray]],
                    twins: list[tuple[CandidateResult, Candidate, np.ndarray]], sur,
                    lik_all: CandidateLikelihood, epoch: float, config: ExplainConfig) -> None:
    """The reported parameters (MAP and 95 % intervals) of the accepted effects, refitted on every
    window, training and held-out: the held-out windows have done their part (the acceptance) and
    hold information the parameters need (a change inside a held-out block is placed only by its
    windows). With several effects, backfitting: each refitted on top of the others at their latest
    values, so that the first, fitted alone, gives back what it took of the second's misfit (a step
    fitted before a knee takes some of the cold spell); passes repeat (``backfit_passes`` at most)
    while a parameter still moves by more than :data:`BACKFIT_SETTLED` of its prior range: two
    effects that overlap in time (a knee whose cold spells fall after a step) trade misfit for
    several passes before they settle, and may settle short of the top of the ridge they trade
    along: then every effect's parameters move together (:func:`.joint.joint_refine`), and a last
    pass refits each from there. Effects tied with the first
    are refitted on top of the later ones; an effect that starts at locate's hinted window without a
    time parameter starts at the window of the hinted span that fits best (:func:`placed_in_span`),
    and each search also starts from the training fit's MAP. The evidences, the acceptance and the fit scores stay those
    of the training windows."""
    every = np.ones(len(lik_all.freq.r), dtype=bool)

    def report(res: CandidateResult, cand: Candidate, fr: FitResult) -> None:
        res.parameters, res.intervals, res.form = cand.describe(fr.theta_map), fr.intervals, cand.form(fr.theta_map)
        t0 = cand.time(fr.theta_map)
        res.time = iso_time(epoch, t0)
        if t0 is not None:
            res.extra["change_window"] = int(np.searchsorted(cand.context.times_s, t0))
        res.extra["estimated_on"] = "all windows"

    def named(cand: Candidate, theta: np.ndarray | None) -> dict[str, float] | None:
        # the training fit's MAP: one more start of the search on every window (with a drifting
        # misfit, a search from random draws alone can stop on a small effect the drift absorbs)
        if theta is None:
            return None
        return {s.name: float(v) for s, v in zip(cand.params(), np.ravel(theta), strict=False)}

    for sweep in range(config.backfit_passes if len(chain) > 1 else 1):
        moved = 0.0
        for k, res in enumerate(chain):
            start = named(*fixed[k])
            others = [f for j, f in enumerate(fixed) if j != k]
            cand = placed_in_span(fixed[k][0], fixed[k][1], others, sur, lik_all) if sweep == 0 else fixed[k][0]
            _, fr = fit_on_top(cand, others, sur, lik_all, every, config.seed + 300 + 10 * sweep + k, config, start)
            moved = max(moved, math.inf if sweep == 0 else _moved(cand, fixed[k][1], fr.theta_map))
            fixed[k] = (cand, fr.theta_map)
            report(res, cand, fr)
        if moved < BACKFIT_SETTLED:
            break
    refined = joint_refine(fixed, sur, lik_all, config.seed + 390) if len(chain) > 1 else None
    if refined is not None:  # the effects moved together to a better point: one more pass from there
        fixed[:] = [(c, th) for (c, _), th in zip(fixed, refined, strict=True)]
        for k, res in enumerate(chain):
            others = [f for j, f in enumerate(fixed) if j != k]
            _, fr = fit_on_top(fixed[k][0], others, sur, lik_all, every, config.seed + 380 + k, config,
                               named(*fixed[k]))
            fixed[k] = (fixed[k][0], fr.theta_map)
            report(res, fixed[k][0], fr)
    for k, (res, cand, theta) in enumerate(twins):
        start = named(cand, theta)
        cand = placed_in_span(cand, theta, fixed[1:], sur, lik_all)
        _, fr = fit_on_top(cand, fixed[1:], sur, lik_all, every, config.seed + 400 + k, config, start)
        report(res, cand, fr)



def shape_terms(fits: list[tuple[CandidateResult, Job, FitResult]], sur: Surrogate, obs: ModalObservations,
                kept: list[int], train: np.ndarray) -> dict[str, float] | None:
    """Each fit's shape term at its MAP (:func:`.shapes.shape_terms_of`), by label."""
    return shape_terms_of([(c.label, c.where, job.cand.modify(np.atleast_2d(fr.theta_map))) for c, job, fr in fits],
                          sur, obs, kept, train)

