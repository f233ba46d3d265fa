"""explain on earthquake series in the time domain: effects modal data cannot show (docs/explain.md).

Input: the structure (a building with a declared base input, docs/interfaces.md §2) and event records
(:class:`shm_ros.core.predict.record.EventRecord`, one per event window of ingest). Steps:

1. the nominal parameters (the file's ``parameters:``) calibrated jointly on every event (MAP of the
   joint time-domain likelihood with the AR(p) residual model, :mod:`.td_fit`); NRMS per event;
2. each time-domain candidate (the amplitude candidates of the registry: stiffness, damping scaled alike in
   every mode, damping added in proportion to the stiffness) at two resolutions: an event playing the part of
   a window (one stiffness or damping factor per event from its amplitude), and within events, a segment of a
   fraction of a second playing that part (the factor from the local amplitude, so a stiffness that softens in
   the strong motion and recovers after it is followed, :mod:`.td_varying`; the added damping within events
   only); fitted with the nominal parameters re-fitted jointly and the candidate's own residual model (AR
   coefficients at its white-noise MAP); evidence gain by Laplace (checked by importance sampling
   once accepted, step 4);
3. held out: a fixed split of events (in amplitude order every ``held_out_every``-th from the second
   strongest down, so the weakest and strongest events stay in the fit: the held-out ones are
   interpolated, and one of them is strong enough to show an amplitude effect); nominal
   and candidate are re-fitted without them and predict them;
4. acceptance (:func:`.select.decide`): gain above the time-domain threshold (``threshold_timedomain.json``,
   calibrated on clean replicates), held-out NRMS improved, 95 % interval of the key parameter
   excluding its null value.

As on the modal path, an explicit phase pipeline on one :class:`EventsRun`: ``_start`` (records,
likelihood, held-out events), ``_nominal``, ``_fit``, ``_decide`` and ``_verdict``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from shm_ros.core.bayes.records import JointTimeDomainLikelihood, RecordSet
from shm_ros.core.config import option
from shm_ros.core.models import build_model
from shm_ros.core.models.base import AffineModel
from shm_ros.core.predict.record import EventRecord
from shm_ros.core.priors import JointPrior, priors_from_specs
from shm_ros.core.structure import StructureSpec
from shm_ros.errors import NumericalFailure

from .candidates._common import amplitude
from .candidates.base import CANDIDATES, Context
from .failures import failed_result, numerical
from .fit_ratio import combined, events_fit_ratio
from .select import decide, shipped_threshold
from .td_fit import (
    EventPosterior,
    Laplace,
    Segments,
    find_map,
    importance_log_z,
    laplace,
    newton_polish,
    spectral_starts,
)
from .td_model import SEGMENT_S, EventData, FactorModel, event_data, segment_amplitudes
from .td_paths import td_form_fits
from .types import CandidateResult, FitScores, Mismatch, Verdict

THRESHOLD_FILE = "threshold_timedomain.json"
MIN_EVENTS = 3  # a calibration set and at least one held-out event
TD_CANDIDATES = ("amplitude_stiffness", "amplitude_damping", "amplitude_added_damping")


@dataclass
class TimeDomainConfig:
    amplitude: str = option("rms_accel_m_s2", "the events' amplitude covariate (per event)",
                            choices=("rms_accel_m_s2", "pga_m_s2"))
    ar_order: int = option(2, "order of each event's autoregressive residual model")
    error_guess: float = option(0.1, "prediction-error scale of the inverse-gamma prior, relative to the records' RMS")
    variance_per_event: bool = option(True, "each event its own prediction-error variance per channel (a model "
                                      "error relative to the response weighs every event alike; else one per "
                                      "channel, which the strongest event's residuals dominate)")
    held_out_every: int = option(3, "in amplitude order, every n-th event from the second strongest down is held out")
    n_importance: int = option(300, "importance samples of the evidence check")
    threshold: float | None = option(None, "log Bayes factor to accept a candidate (unset: the shipped "
                                     "calibration, threshold_timedomain.json)")
    tie_nats: float = option(2.0, "candidates within this many nats of the best are reported together")
    seed: int = option(0, "random seed (starting points, importance sampling)")
    candidates: list[str] = option(list(TD_CANDIDATES), "time-domain candidates tried (registry labels)")
    # per_event: one factor per event from its amplitude; within_event: one per segment of an event
    # from the local amplitude (td_varying.py), so softening during the strong motion is followed
    resolutions: list[str] = option(["per_event", "within_event"], "resolutions tried: per_event (a factor "
                                    "per event), within_event (per segment of an event)")
    segment_s: float = option(SEGMENT_S, "within-event segment length, s")


def held_out_events(amplitude: np.ndarray, every: int) -> np.ndarray:
    """(E,) bool: counted down from the strongest, ranks 2, 2 + every, ... (never the weakest or the
    strongest): an amplitude effect is tested where it shows, so the second strongest event is always
    among the held-out ones (a weak event is predicted alike with and without the effect)."""
    rank = np.argsort(np.argsort(-np.asarray(amplitude, float)))  # 0: the strongest
    held = (rank % max(every, 2) == 1) & (rank < amplitude.size - 1)
    return held if (~held).sum() >= 2 else np.zeros(amplitude.size, bool)


def _scores(nrms: np.ndarray) -> FitScores:
    return FitScores(nrms_pct=float(np.mean(nrms)) if nrms.size else None)


@dataclass
class EventsRun:
    """One time-domain explain run: its inputs and what each phase adds (the phases below, in order)."""

    cfg: TimeDomainConfig
    say: Callable[[str], None]
    model: AffineModel
    data: EventData
    lik: JointTimeDomainLikelihood
    prior: JointPrior
    rng: np.random.Generator
    amp: np.ndarray
    train: np.ndarray
    test: np.ndarray
    # the nominal model
    nominal: EventPosterior = field(init=False)
    u_n: np.ndarray = field(init=False)
    lap_n: Laplace = field(init=False)
    nominal_ar: list = field(init=False)
    before: np.ndarray = field(init=False)
    held_before: np.ndarray = field(init=False)
    # candidates
    results: list[CandidateResult] = field(default_factory=list)
    failed: list[CandidateResult] = field(default_factory=list)
    checks: dict[str, _Pending] = field(default_factory=dict)  # per label: what the evidence check needs
    keys: dict[str, tuple[str, float | None]] = field(default_factory=dict)
    accepted: list[CandidateResult] = field(default_factory=list)
    thr: dict = field(default_factory=dict)

    @property
    def n_ev(self) -> int:
        return len(self.data.records)

    @property
    def strongest(self) -> int:
        return int(np.argmax(self.amp))  # the event the report draws


def explain_events(events: list[EventRecord], spec: StructureSpec, config: TimeDomainConfig | None = None,
                   progress: Callable[[str], None] | None = None) -> Verdict:
    """The time-domain verdict (module docstring): the phases in order on one :class:`EventsRun`."""
    run = _start(events, spec, config or TimeDomainConfig(), progress or (lambda _m: None))
    for phase in (_nominal, _fit, _decide):
        phase(run)
    return _verdict(run)


def _start(events: list[EventRecord], spec: StructureSpec, cfg: TimeDomainConfig, say) -> EventsRun:
    """The records, the joint likelihood, the held-out events."""
    model = build_model(spec)
    data = event_data(events)
    lik = JointTimeDomainLikelihood(FactorModel.of(model), RecordSet(data.records), ar_order=cfg.ar_order,
                                    error_guess=cfg.error_guess, per_record=cfg.variance_per_event)
    every = np.arange(len(data.records))
    amp = data.covariates[cfg.amplitude]
    held = held_out_events(amp, cfg.held_out_every)
    return EventsRun(cfg, say, model, data, lik, priors_from_specs(spec.parameters), np.random.default_rng(cfg.seed),
                     amp, every[~held], every[held])


def _nominal(run: EventsRun) -> None:
    """The nominal parameters calibrated on every event (its residual model fixed for every comparison)
    and on the training events alone (the held-out score)."""
    run.say("calibrating the nominal parameters on every event")
    nominal = run.nominal = EventPosterior(run.lik, run.prior, None)
    u_w, _ = find_map(nominal, spectral_starts(nominal, run.rng))
    nominal.fix_ar(u_w)  # the residual model of every comparison below
    run.u_n, f_n = newton_polish(nominal, *find_map(nominal, [u_w]))
    run.lap_n = laplace(nominal, run.u_n, f_n)
    run.nominal_ar = nominal.ar_state()
    run.before = nominal.nrms(run.u_n, np.arange(run.n_ev))
    nom_tr = EventPosterior(run.lik, run.prior, None, run.train)
    u_ntr, _ = find_map(nom_tr, [run.u_n])
    run.held_before = nom_tr.nrms(u_ntr, run.test)


def _fit(run: EventsRun) -> None:
    """Every time-domain candidate at each resolution; a named numerical failure fails that fit only."""
    cfg, data = run.cfg, run.data
    t0 = min(data.start_ns) if data.start_ns else 0
    every = np.arange(run.n_ev)
    ctx = Context(times_s=(np.array(data.start_ns, float) - t0) / 1e9 if data.start_ns else every.astype(float),
                  covariates=dict(data.covariates), hints={"covariate": cfg.amplitude})
    period = 1.0 / float(run.model.modes(None, 1).frequencies_hz[0])
    seg_amp, seg_len = segment_amplitudes(data.records, period, cfg.segment_s)
    segments = Segments(seg_len, [a.size for a in seg_amp], np.concatenate(seg_amp) ** 2)
    seg_t = np.concatenate([ctx.times_s[e] + np.arange(a.size) * seg_len[e] * data.records[e].dt
                            for e, a in enumerate(seg_amp)])
    ctx_in = Context(times_s=seg_t, covariates={"rms_accel_m_s2": np.concatenate(seg_amp)},
                     hints={"covariate": "rms_accel_m_s2"})
    if run.n_ev < MIN_EVENTS:
        run.say(f"{run.n_ev} event(s): too few to fit a candidate and score it on held-out events")
        return
    for label in cfg.candidates:
        only = getattr(CANDIDATES.get(label), "resolutions", None)  # a candidate may need one resolution
        for res in (r for r in cfg.resolutions if only is None or r in only):
            run.say(f"fitting {label} ({res.replace('_', ' ')})")
            within = res == "within_event"
            cand = CANDIDATES.get(label)("EI", ctx_in if within else ctx)
            try:
                with numerical(f"{cand.label} ({res.replace('_', ' ')})"):
                    r, pending = _fit_candidate(cand, run.lik, run.prior, run.u_n, run.lap_n.log_z, run.train,
                                                run.test, segments if within else None, run.strongest)
            except NumericalFailure as exc:  # named numerical failures only: the candidate failed
                run.failed.append(failed_result(cand.vocabulary, f"{cand.label}/{res}", cand.group, exc,
                                                cand.explanation))
                continue
            r.extra["nrms_per_event"] = r.extra.pop("_nrms").tolist()
            r.extra["resolution"] = res
            r.form_fits, form = td_form_fits(np.asarray(r.extra["nrms_per_event"])[run.train], run.amp[run.train])
            r.extra.update(form)
            if within:
                r.label = f"{r.label}/within_event"
                r.extra.update(period_s=period, segment_s=cfg.segment_s)
                r.form = (f"{r.form} within each event: a = RMS acceleration of the outputs over one period of "
                          f"the first mode ({period:.2f} s), per {cfg.segment_s:g} s")
            run.results.append(r)
            run.checks[r.label] = pending
            run.keys[r.label] = (cand.key_parameter(), cand.params()[0].null)


def _decide(run: EventsRun) -> None:
    """Acceptance, and the second estimator of the accepted candidates' evidence."""
    cfg = run.cfg
    run.thr = _threshold(cfg)
    run.accepted = decide(run.results, run.keys, float(run.thr["log_bayes_factor"]), _scores(run.held_before), None,
                          cfg.tie_nats)
    if run.accepted:  # the second estimator, for the accepted candidates (as on the modal path)
        run.say("checking the accepted candidates' evidence by importance sampling")
        run.nominal.set_ar(run.nominal_ar)
        chk_n = importance_log_z(run.nominal, run.lap_n, cfg.n_importance, run.rng)
        for c in run.accepted:
            _check(c, run.checks[c.label], chk_n, cfg.n_importance, run.rng)
        run.nominal.set_ar(run.nominal_ar)


def _verdict(run: EventsRun) -> Verdict:
    """Scores before and after, the mismatch, the fit ratio, notes and the figures' numbers."""
    cfg, data, accepted, before, n_ev = run.cfg, run.data, run.accepted, run.before, run.n_ev
    after = np.array(accepted[0].extra["nrms_per_event"]) if accepted else before
    held_after = (accepted[0].held_out_after if accepted and accepted[0].held_out_after
                  else _scores(run.held_before))
    corr = float(np.corrcoef(run.amp, before)[0, 1]) if n_ev > 2 and np.std(before) > 0 else 0.0
    mismatch = Mismatch(modes=[], sensors=list(data.records[0].channel_ids), covariates={cfg.amplitude: corr},
                        summary=(f"nominal model calibrated on {n_ev} events: NRMS {np.mean(before):.1f} % "
                                 f"(per event {', '.join(f'{v:.1f}' for v in before)}); correlation of the "
                                 f"per-event NRMS with {cfg.amplitude}: {corr:+.2f}"))
    theta = dict(zip(run.lik.model.parameter_names[:len(run.u_n)], map(float, run.u_n), strict=True))
    examples = {r.label: r.extra.pop("_example") for r in run.results}
    ratio = combined(events_fit_ratio(after, data.noise_nrms if data.noise_nrms is not None
                                      else np.full(n_ev, np.nan)))
    notes = [*data.notes, f"time domain: {n_ev} events, held out {[int(i) for i in run.test]} (amplitude order), "
             f"nominal parameters at the MAP: {theta}"]
    if n_ev < MIN_EVENTS:
        notes.append(f"{n_ev} event(s): no candidate was fitted (at least {MIN_EVENTS} are needed, a calibration "
                     "set and a held-out event); the nominal model's fit is reported")
    notes += [f"{c.label}: {c.reasons[0]}" for c in run.failed]
    figures: dict = {"events": {"window_ids": data.window_ids, cfg.amplitude: run.amp.tolist(),
                                "nrms_before": before.tolist(), "nrms_after": after.tolist(),
                                "held_out": [int(i) for i in run.test], "nominal_parameters": theta}}
    s = run.strongest
    rec = data.records[s]
    figures["events"]["example"] = {
        "window_id": data.window_ids[s], "channel": rec.channel_ids[-1], "dt": rec.dt,
        "measured": rec.outputs[:, -1].tolist(), "before": run.nominal.predict(run.u_n, s)[:, -1].tolist(),
        "after": examples[accepted[0].label] if accepted else None}
    if accepted:
        figures["form"] = _form_curve(accepted[0])
    return Verdict(mismatch=mismatch, missing_physics=accepted, tried=run.results + run.failed,
                   fit_before=_scores(before), fit_after=_scores(after), held_out_before=_scores(run.held_before),
                   held_out_after=held_after, threshold=run.thr, notes=notes, figures=figures, fit_ratio=ratio[0],
                   fit_ratio_details=ratio[1])


def _form_curve(c: CandidateResult) -> dict:
    """The accepted effect's factor against the amplitude, from small amplitude, with its 95 % band."""
    (name, k), (lo, hi) = next(iter(c.parameters.items())), next(iter(c.intervals.values()))
    a = np.linspace(0.0, float(c.extra["amplitude_max"]), 60)
    stiff = c.extra["acts_on"] == "stiffness"
    f = (lambda kk: 1.0 / (1.0 + kk * a)) if stiff else (lambda kk: 1.0 + kk * a)
    within = c.extra.get("resolution") == "within_event"
    return {"x": a.tolist(), "y": f(k).tolist(), "lower": np.minimum(f(lo), f(hi)).tolist(),
            "upper": np.maximum(f(lo), f(hi)).tolist(),
            "x_label": ("local RMS acceleration over one period, m/s^2" if within else
                        "event RMS acceleration over the strong motion, m/s^2"),
            "y_label": f"{c.extra['acts_on']} factor (1 at small amplitude)",
            "title": f"{c.name}: {c.extra['acts_on']} against amplitude ({name} = {k:.3g})"}


def _threshold(cfg: TimeDomainConfig) -> dict:
    if cfg.threshold is not None:
        return {"log_bayes_factor": float(cfg.threshold), "source": "config"}
    return shipped_threshold(THRESHOLD_FILE)


@dataclass
class _Pending:
    """A candidate's posterior, Laplace fit and residual model, for its evidence check."""

    post: EventPosterior
    lap: Laplace
    ar: list


def _check(c: CandidateResult, p: _Pending, chk_n: tuple[float, float], n: int, rng: np.random.Generator) -> None:
    """Importance-sampling check of an accepted candidate's evidence gain (``check_agrees``: within
    max(0.5, 3 combined standard errors))."""
    p.post.set_ar(p.ar)
    chk, chk_se = importance_log_z(p.post, p.lap, n, rng)
    c.log_evidence_gain_check = float(chk - chk_n[0])
    err = math.hypot(chk_se, chk_n[1])
    c.extra["check_err"] = err
    c.extra["check_agrees"] = bool(abs(c.log_evidence_gain - c.log_evidence_gain_check) <= max(0.5, 3 * err))


def _fit_candidate(cand, lik, prior, u_n, log_z_n, train, test, segments=None,
                   example: int = 0) -> tuple[CandidateResult, _Pending]:
    post = EventPosterior(lik, prior, cand, segments=segments)
    specs = post.specs
    nominal_ar = post.ar_state()
    # the candidate's own residual model, as the nominal's: AR coefficients at its white-noise MAP
    # (the nominal's residual is the misfit the effect leaves; whitened by its AR model, that misfit
    # would cost the candidate's fit little, and its MAP would stop short of the effect)
    post.white()
    grid = np.r_[0.0, np.logspace(-4, 0, 13)]  # the effect's place in its prior range: a coarse scan first
    pts = np.column_stack([np.tile(u_n, (grid.size, 1)), grid])
    f = post(pts)
    starts = [pts[i] for i in np.argsort(-f)[:2]]
    u_w, _ = find_map(post, starts)
    post.fix_ar(u_w)
    u_c, f_c = newton_polish(post, *find_map(post, [u_w]))
    gain_at_map = f_c - nominal_at(post, u_c)
    lap = laplace(post, u_c, f_c)
    gain = lap.log_z - log_z_n
    pending = _Pending(post, lap, post.ar_state())
    nb = post.nb
    sd = math.sqrt(max(lap.cov[nb, nb], 0.0))
    u_lo, u_hi = max(u_c[nb] - 1.96 * sd, 0.0), min(u_c[nb] + 1.96 * sd, 1.0)
    phi = post.phi(np.array([u_c, np.r_[u_c[:nb], u_lo], np.r_[u_c[:nb], u_hi]]))[:, 0]
    after = post.nrms(u_c, np.arange(len(lik.parts)))
    post_tr = EventPosterior(lik, prior, cand, train, segments=segments)
    u_tr, _ = find_map(post_tr, [u_c])
    held = post_tr.nrms(u_tr, test)
    post.set_ar(nominal_ar)
    s, d, g = post.factors(u_c[None, :])
    acts_on = "damping" if cand.vocabulary.endswith("damping") else "stiffness"
    column = ("stiffness", "damping", "added_damping")[post.varies]
    # the model's first-mode inherent damping ratio at this fit: what a damping factor multiplies
    # (at small amplitude: the factors are relative to the fitted events' average, raw / G)
    raw = cand.modify(post.phi(u_c[None, :]))
    raw_d = raw.damping if raw.damping is not None else np.ones_like(d)
    raw_s = np.asarray(raw.groups.get("EI", np.ones_like(s)), float)
    # G: the fitted factors are raw / G (relative to the fitted events' average, EventPosterior.factors)
    norm = float(raw_s[0, 0] / s[0, 0]) if acts_on == "stiffness" else float(raw_d[0, 0] / d[0, 0])
    zeta1 = float(lik.model.damping_ratios_at(np.r_[u_c[:nb], 1.0, 1.0, 0.0])[0]) * float(d[0, 0] / raw_d[0, 0])
    # the first mode's damping factor per event: inherent and added (FactorModel's g is in units of it)
    first_mode = d + g
    return CandidateResult(
        name=cand.vocabulary, label=cand.label, form=cand.form(phi[:1]), where=cand.group,
        parameters={specs[0].name: float(phi[0])}, intervals={specs[0].name: (float(phi[1]), float(phi[2]))},
        log_evidence_gain=float(gain), log_evidence_gain_check=None, log_evidence_gain_err=0.0,
        prior_sensitivity={}, explanation=cand.explanation, fit_after=_scores(after), held_out_after=_scores(held),
        extra={"_nrms": after, "_example": post.predict(u_c, example)[:, -1].tolist(),
               "amplitude_max": float(np.max(amplitude(cand.context)[1])), "factor_norm": norm,
               "held_out_metric": "nrms_pct", "acts_on": acts_on, "gain_at_map": float(gain_at_map),
               "factors": _per_event((s if acts_on == "stiffness" else first_mode)[0], segments),
               "factor_column": column,
               "nominal_parameters": dict(zip(lik.model.parameter_names[:nb], map(float, u_c[:nb]), strict=True)),
               "inherent_damping_ratio_1": zeta1}), pending


def _per_event(f: np.ndarray, segments: Segments | None) -> list[float]:
    """A fit's factors per event (within events: their geometric mean over each event's segments)."""
    if segments is None:
        return f.tolist()
    o = segments.offsets
    return [float(np.exp(np.mean(np.log(f[o[e]:o[e + 1]])))) for e in range(len(segments.counts))]


def nominal_at(post: EventPosterior, u: np.ndarray) -> float:
    """log posterior of the same nominal parameters without the effect (the effect at its null)."""
    v = u.copy()
    v[post.nb:] = 0.0
    return float(post(v)[0])

