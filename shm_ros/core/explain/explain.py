"""The whole chain: tracked-modes table + nominal structure -> :class:`~.types.Verdict`.

An explicit phase pipeline on one :class:`Run` (``explain`` runs them in order): ``_start`` (time
order, held-out split), ``_baseline``, ``_locate_phase``, ``_fit``, ``_decide``, ``_second_round``,
``_final_estimates``, ``_catch_all``, ``_unmodelled`` and ``_verdict`` (figures' numbers, whiteness,
fit ratio); each reads and adds fields of the run.

1. **Baseline.** The tracked modes are paired once with the nominal model's modes (frequency and
   MAC gates, :func:`shm_ros.core.bayes.pairing.gated_pairing`); modes that pair with none are
   ``unmodelled_modes``. The nominal parameters are calibrated to the training windows' mean
   frequencies (MAP: their priors and per-mode model-form offsets of unknown scale) and then kept
   fixed: the per-mode offsets absorb constant misfit, and the mean part of the candidates'
   likelihood integrates out a linearised re-calibration (:mod:`.likelihood`).
2. **Split.** Windows fall in blocks (a third of a day, or W/8 windows); every ``held_out_every``-th
   block is held out of every fit and scores it afterwards. An effect that starts at a moment the
   training windows place only within a held-out block is judged on the other held-out windows
   (:func:`.scoring.judged_windows`).
3. **Locate** (:mod:`.locate`, when present) proposes candidates and groups from the residuals;
   without it every registered candidate is tried on its default groups.
4. **Fit** every proposal (:mod:`.fit`: MAP, evidence by importance sampling, intervals, prior
   sensitivity) on the surrogate (:mod:`.surrogate`), the catch-all in closed form; the nested-sampling
   check for those that clear the threshold.
5. **Select** (:mod:`.select`) and score the fit before / after, on training and held-out windows;
   candidates tied on frequencies are compared again with the identified shapes (:mod:`.shapes`),
   and more effects are fitted on top of the accepted one (the second round, :mod:`.rounds`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy.optimize import minimize

from shm_ros.core.bayes.pairing import PairingGate, gated_pairing
from shm_ros.core.models import build_model
from shm_ros.core.observations import ModalObservations
from shm_ros.core.priors import priors_from_specs
from shm_ros.core.structure import StructureSpec
from shm_ros.errors import InputError, NoWindowsError, NumericalFailure

from .candidates.base import CANDIDATES, Candidate, Context
from .config import ExplainConfig, MisfitCorrelation
from .drift import Timing
from .failures import failed_result, numerical
from .fit import Box, FitResult, evidence_check, fit
from .fit_ratio import combined, modal_fit_ratio
from .groups import GroupModel, build_groups
from .jobs import Job, iso_time, result
from .likelihood import S_RANGE, CandidateLikelihood, catch_all_gain
from .rounds import final_estimates, more_effects, shape_terms
from .scoring import damping_scores, scatter, scores
from .select import decide, shipped_threshold
from .shapes import break_tie
from .surrogate import Surrogate
from .types import Baseline, CandidateResult, FitScores, Mismatch, Proposal, Verdict
from .whiteness import residual_whiteness

Progress = Callable[[str, float], None]
DRIFT_NOTE_NATS = 5.0  # a drift in the nominal misfit this strongly supported is said in a note
SPARSE_WINDOWS = 40  # fewer training windows: sparse records (a few events), every candidate is tried
# held-out blocks of a campaign of days: a third of a day, so that every n-th block (n = 4) goes round
# the times of day, and a change the training windows place only within a held-out block (its time is
# free across it) is followed by other held-out blocks, which judge it (scoring.judged_windows)
BLOCK_S = 86400.0 / 3


# -- baseline ----------------------------------------------------------------------------------------

def split(times_s: np.ndarray, config: ExplainConfig) -> np.ndarray:
    """Training mask (W,): every ``held_out_every``-th block of windows is held out (a block: a third
    of a day of windows (``BLOCK_S``) in campaigns of four days or more, else W/8 windows, or one
    window of sparse records, fewer than ``SPARSE_WINDOWS``: held-out events interleaved with the
    training ones)."""
    W = len(times_s)
    if config.block_windows > 0:
        block = np.arange(W) // config.block_windows
    elif W < SPARSE_WINDOWS:  # sparse records (events days apart): every n-th event, interleaved
        block = np.arange(W)
    elif times_s[-1] - times_s[0] >= 4 * 86400.0:
        block = ((times_s - times_s[0]) // BLOCK_S).astype(int)
    else:
        block = np.arange(W) // max(W // 8, 1)
    return (block % config.held_out_every) != config.held_out_every - 1


def _model_modes(model, theta: np.ndarray, n: int, sensors: list[str]):
    sol = model.modes(theta, n)
    phi = None
    if sensors:
        try:
            phi = model.sensor_matrix(sensors) @ sol.shapes
        except KeyError:
            phi = None
    return sol.frequencies_hz, phi


MAC_RELAXED = 0.5  # an in-plane mode whose shape the model-form error degrades still reaches it


def _second_chance(pr, mode_numbers):
    """Pair an observed mode that failed only the MAC gate with its nearest model mode when no other
    observed mode took that model mode and the MAC still reaches ``MAC_RELAXED``: a higher in-plane
    mode whose shape at the sensors the model represents poorly (shear deformation, misplaced
    sensors; MAC 0.7-0.8 on the simulated girders) is in the model's class. Modes of another class
    (lateral, torsional) reach MAC 0.2 or less with the nearest vertical mode, or lose the one-to-one
    pairing to the mode that fits it."""
    from dataclasses import replace

    obs_idx, mod_idx = list(pr.observed), list(pr.model_index)
    keep = []
    for u in pr.unmodelled:
        j = u.nearest_model_mode - 1
        if (u.reason == "mac" and u.mac is not None and u.mac >= MAC_RELAXED and u.mode in mode_numbers
                and j not in mod_idx):
            obs_idx.append(mode_numbers.index(u.mode))
            mod_idx.append(j)
        else:
            keep.append(u)
    if len(keep) == len(pr.unmodelled):
        return pr
    order = np.argsort(obs_idx)
    return replace(pr, observed=np.asarray(obs_idx)[order], model_index=np.asarray(mod_idx)[order], unmodelled=keep)


def calibrate_baseline(obs: ModalObservations, spec: StructureSpec, train: np.ndarray,
                       config: ExplainConfig) -> tuple[Baseline, np.ndarray]:
    """Pair, calibrate the nominal parameters (MAP), pair again; returns the baseline and the
    nominal parameters' log-frequency sensitivities (K, p)."""
    model = build_model(spec)
    n_model = min(obs.n_modes + 4, model.n_dof)
    sensors = list(obs.sensor_ids) if obs.has_shapes else []
    gate = PairingGate(config.frequency_gate, config.mac_gate)
    f_mean = np.nanmean(obs.frequencies_hz[train], axis=0)
    ref = obs.reference_shapes()

    def pairing(theta, scale: float = 1.0):
        f, phi = _model_modes(model, theta, n_model, sensors)
        return _second_chance(gated_pairing(f_mean, ref if phi is not None else None, scale * f, phi, gate,
                                            obs.mode_numbers), obs.mode_numbers)

    names = [p.name for p in spec.parameters]
    theta0 = model.nominal_theta()
    pr = pairing(theta0)
    if len(pr.observed) < min(2, int(np.isfinite(f_mean).sum())):
        # a nominal model further off than the gate everywhere: pair after one common frequency scale
        # (the lowest observed modes on the lowest model modes), then calibrate from that pairing
        fo = np.sort(f_mean[np.isfinite(f_mean)])
        fm = np.sort(_model_modes(model, theta0, n_model, [])[0])[:fo.size]
        scaled = pairing(theta0, float(np.median(fo[:fm.size] / fm)))
        if len(scaled.observed) > len(pr.observed):
            pr = scaled
    if not len(pr.observed):
        raise InputError(f"no tracked mode pairs with a mode of the structure's model (observed "
                         f"{', '.join(f'{x:.3g}' for x in f_mean[np.isfinite(f_mean)])} Hz; the model's lowest "
                         f"{', '.join(f'{x:.3g}' for x in _model_modes(model, theta0, n_model, [])[0][:4])} Hz): "
                         "check the structure file's masses, stiffnesses and units")
    if names:
        prior = priors_from_specs(spec.parameters)
        s2 = np.exp(np.linspace(np.log(S_RANGE[0]), np.log(S_RANGE[1]), 41)) ** 2

        def neg_post(lx):
            th = np.exp(lx)
            f = model.modes(th, n_model).frequencies_hz[pr.model_index]
            y = np.log(f_mean[pr.observed]) - np.log(f)
            ll = -0.5 * len(y) * np.log(2 * np.pi * s2) - 0.5 * float(y @ y) / s2
            mx = ll.max()
            lp = float(prior.logpdf(th[None])[0]) + float(np.sum(lx))  # density of ln theta
            return -(mx + math.log(np.mean(np.exp(ll - mx))) + lp)

        res = minimize(neg_post, np.zeros(len(names)), method="Nelder-Mead",
                       options={"xatol": 1e-6, "fatol": 1e-8, "maxfev": 400 * len(names)})
        theta = np.exp(res.x)
        pr2 = pairing(theta)
        if not pr2.same_as(pr):
            pr = pr2
            res = minimize(neg_post, res.x, method="Nelder-Mead", options={"xatol": 1e-6, "fatol": 1e-8})
            theta = np.exp(res.x)
    else:
        theta = theta0
    f_model, _ = _model_modes(model, theta, n_model, [])
    kept = pr.observed
    mi = pr.model_index
    logres = np.log(obs.frequencies_hz[:, kept]) - np.log(f_model[mi])[None]
    J = np.zeros((len(kept), len(names)))
    for j in range(len(names)):  # d ln f / d ln theta_j by central differences
        e = np.zeros(len(names))
        e[j] = 1e-4
        fp = model.modes(theta * np.exp(e), n_model).frequencies_hz[mi]
        fm = model.modes(theta * np.exp(-e), n_model).frequencies_hz[mi]
        J[:, j] = (np.log(fp) - np.log(fm)) / 2e-4
    seen = np.mean(np.isfinite(obs.frequencies_hz), axis=0)
    unpaired = []
    for u in pr.unmodelled:
        d = u.to_dict()
        if u.mode is not None and u.mode in obs.mode_numbers:
            d["fraction_of_windows"] = float(seen[obs.mode_numbers.index(u.mode)])
        unpaired.append(d)
    unpaired += [dict(u) for u in obs.unmodelled_modes]
    base = Baseline(mode_numbers=[obs.mode_numbers[k] for k in kept], model_index=[int(i) for i in mi],
                    log_residual=logres, f_model=f_model[mi], sensitivities={},
                    theta=dict(zip(names, (float(t) for t in theta), strict=True)), unpaired=unpaired, train=train)
    return base, J



# -- proposals ---------------------------------------------------------------------------------------

def default_proposals(groups: GroupModel) -> list[Proposal]:
    out = []
    for name in CANDIDATES.names():
        cls = CANDIDATES.get(name)
        for pattern in getattr(cls, "default_groups", ("EI",)):
            if pattern.endswith(":*"):
                gs = [g for g in groups.names() if g.startswith(pattern[:-1])]
            else:
                gs = [pattern] if pattern in groups.groups else []
            out += [Proposal(name, g, "tried on its default group (no residual analysis)") for g in gs]
    return out


def _locate(obs, baseline, context, config, groups) -> tuple[Mismatch, list[Proposal], list[str]]:
    try:
        from .locate import locate
    except ImportError:
        props = default_proposals(groups)
        return (Mismatch(modes=list(baseline.mode_numbers), sensors=list(obs.sensor_ids), covariates={},
                         summary="residual analysis not available: every candidate tried"), props,
                ["locate is not available: every registered candidate was tried on its default groups"])
    from .locate import LocateConfig

    mismatch, props = locate(obs, baseline, context, LocateConfig(min_unpaired_fraction=config.min_unpaired_fraction))
    # damping candidates act on the modal damping, not on a group of the model
    return mismatch, [p for p in props if (p.group in groups.groups or p.group == "damping")
                      and p.candidate in CANDIDATES], []


# -- catch-all ---------------------------------------------------------------------------------------

def catch_all_basis(context: Context) -> tuple[np.ndarray, list[str]]:
    """Smooth functions of the covariates and of time (W, p), and what each column is."""
    t = np.asarray(context.times_s, dtype=float)
    cols, names = [], []
    span = max(float(t[-1] - t[0]), 1.0)
    cols.append((t - t[0]) / span)
    names.append("time trend")
    for q in (0.2, 0.4, 0.6, 0.8):
        cols.append((t >= t[0] + q * span).astype(float))
        names.append(f"step at {q:.0%} of the campaign")
    for key in ("temperature_c", "rms_accel_m_s2", "pga_m_s2"):
        v = context.covariates.get(key)
        if v is None or not np.isfinite(v).any() or np.nanstd(v) == 0:
            continue
        v = np.asarray(v, dtype=float)
        if key != "temperature_c":
            v = np.log(np.maximum(v, np.nanmin(v[v > 0]) if (v > 0).any() else 1e-9))
        v = np.where(np.isfinite(v), v, np.nanmedian(v))
        cols.append(v)
        names.append(key)
        for q in (0.25, 0.5, 0.75):
            c = float(np.quantile(v, q))
            cols.append(np.minimum(v - c, 0.0))
            names.append(f"{key} below {c:.3g}")
    return np.column_stack(cols), names



# -- ties: the shapes as a second witness ---------------------------------------------------------------

def _shape_tiebreak(tied: list[CandidateResult], jobs, sur: Surrogate, obs: ModalObservations, kept: list[int],
                    train: np.ndarray, tie_nats: float) -> list[CandidateResult]:
    """Candidates tied on frequencies compared again with their shapes (:func:`.shapes.break_tie`)."""
    ll = shape_terms([(c, *jobs[c.label]) for c in tied], sur, obs, kept, train) if len(tied) > 1 else None
    return tied if ll is None else break_tie(tied, ll, tie_nats)



# -- entry point -------------------------------------------------------------------------------------

@dataclass
class Run:
    """One explain run: its inputs, and what each phase adds (the phases below, in order)."""

    obs: ModalObservations
    spec: StructureSpec
    config: ExplainConfig
    say: Progress
    notes: list[str]
    times_s: np.ndarray
    epoch: float
    train: np.ndarray
    # baseline
    base: Baseline = field(init=False)
    J: np.ndarray = field(init=False)
    sur: Surrogate = field(init=False)
    kept: list[int] = field(init=False)
    r_all: np.ndarray = field(init=False)
    rd_all: np.ndarray | None = field(init=False)
    z_all: np.ndarray | None = field(init=False)
    context: Context = field(init=False)
    lik: CandidateLikelihood = field(init=False)
    fit_before: FitScores = field(init=False)
    held_before: FitScores = field(init=False)
    noise: dict[str, float | None] = field(init=False)
    # locate
    groups: GroupModel = field(init=False)
    mismatch: Mismatch = field(init=False)
    proposals: list[Proposal] = field(init=False)
    threshold: float = field(init=False)
    threshold_info: dict[str, Any] = field(init=False)
    # fit, decide, second round, final estimates, catch-all
    tried: list[CandidateResult] = field(default_factory=list)
    failed: list[CandidateResult] = field(default_factory=list)
    keys: dict[str, tuple[str, float | None]] = field(default_factory=dict)
    jobs: dict[str, tuple[Job, FitResult]] = field(default_factory=dict)
    accepted: list[CandidateResult] = field(default_factory=list)
    chain: list[CandidateResult] = field(default_factory=list)  # the accepted effects fitted one on another
    fixed: list[tuple[Candidate, np.ndarray]] = field(default_factory=list)
    last: tuple[Job, np.ndarray] | None = None  # the latest accepted effect's job and MAP (training windows)
    form_of: tuple[Candidate, np.ndarray] | None = None
    fit_after: FitScores | None = None
    held_after: FitScores | None = None
    catch: float | None = None
    unexplained: dict[str, Any] | None = None


def explain(obs: ModalObservations, spec: StructureSpec, config: ExplainConfig | None = None,
            progress: Progress | None = None) -> Verdict:
    """Which physics the nominal model is missing, fitted and compared by evidence (module docstring):
    the phases in order on one :class:`Run`."""
    run = _start(obs, spec, config or ExplainConfig(), progress or (lambda stage, frac: None))
    for phase in (_baseline, _locate_phase, _fit, _decide, _second_round, _final_estimates, _catch_all,
                  _unmodelled):
        phase(run)
    return _verdict(run)


def _start(obs: ModalObservations, spec: StructureSpec, config: ExplainConfig, say: Progress) -> Run:
    """The windows in time order without modes never found, the held-out split."""
    if obs.n_windows == 0:
        raise NoWindowsError("the modal data hold no window")
    obs, dropped = obs.without_empty_modes()
    if obs.n_modes == 0:
        raise NoWindowsError(f"none of the {obs.n_windows} window(s) holds an identified mode")
    obs = obs.subset(np.argsort(obs.times))
    times_s = obs.times - obs.times[0]
    return Run(obs, spec, config, say, [f"mode {m} has no frequency in any window; left out" for m in dropped],
               times_s, float(obs.times[0]) if obs.time_kind == "iso" else 0.0, split(times_s, config))


def _timing(run: Run, mask: np.ndarray) -> Timing | None:
    """The times of the windows in ``mask`` for a misfit with drift (:mod:`.drift`), or None
    (independent misfit: so configured, or a sparse record)."""
    if run.config.misfit_correlation != MisfitCorrelation.DRIFT:
        return None
    return Timing.of(run.times_s[mask], SPARSE_WINDOWS)


def _drift_note(run: Run) -> None:
    """Say which modes' nominal misfit drifts (:mod:`.drift`): a slow driver no covariate explains,
    taken as noise by every model compared, not as an effect."""
    strong = {run.base.mode_numbers[k]: v for k, v in run.lik.drift().items() if v[0] > DRIFT_NOTE_NATS}
    if strong:
        run.notes.append("the nominal misfit drifts from window to window in modes " + ", ".join(
            f"{m} (drift over none {bf:.0f} nats, drift-to-scatter ratio {lam:.2g})" for m, (bf, lam) in strong.items())
            + ": a slow driver no covariate explains (moisture, a structure temperature the sensor misses, a "
            "drifting gauge), taken as noise by every candidate, not as an effect")


def _baseline(run: Run) -> None:
    """Calibrated nominal model, its groups and surrogate, the misfit per window, the likelihood and
    the scores before any effect."""
    obs, config, train = run.obs, run.config, run.train
    run.say("baseline", 0.0)
    run.base, run.J = calibrate_baseline(obs, run.spec, train, config)
    run.groups = build_groups(run.spec, run.base.theta)
    run.sur = Surrogate(run.groups, run.base.model_index)
    run.base.sensitivities = run.sur.sensitivities()
    run.kept = [obs.mode_numbers.index(m) for m in run.base.mode_numbers]
    # keep the baseline's pairing frequencies consistent with the group model (the same matrices)
    run.r_all = run.base.log_residual + np.log(run.base.f_model)[None] - run.sur.log_f_base[None]
    run.z_all = None if obs.damping is None else obs.damping[:, run.kept]
    run.rd_all = None if run.z_all is None else np.log(np.where(run.z_all > 0, run.z_all, np.nan))
    covariates = {k: np.asarray(v, float) for k, v in obs.covariates.items()}
    for short, name in (("rms_accel", "rms_accel_m_s2"), ("pga", "pga_m_s2"), ("temperature", "temperature_c")):
        if short in covariates and name not in covariates:  # tables that name covariates without units
            covariates[name] = covariates.pop(short)
    run.context = Context(times_s=run.times_s, covariates=covariates, start_epoch_s=run.epoch)
    run.lik = CandidateLikelihood(run.r_all[train], run.J, None if run.rd_all is None else run.rd_all[train],
                                  tau=config.effect_form_error, noise_guess=config.noise_guess,
                                  damping_noise_guess=config.damping_noise_guess, timing=_timing(run, train))
    _drift_note(run)
    run.fit_before, run.held_before = scores(run.r_all, None, train)
    run.fit_before.damping_rmse_pct, run.held_before.damping_rmse_pct = damping_scores(run.z_all, None, train)
    run.noise = {"frequency_pct": scatter(run.r_all), "damping_points": scatter(run.z_all)}


def _locate_phase(run: Run) -> None:
    """Where the misfit is and what to fit (training windows only), and the threshold in force."""
    run.mismatch, run.proposals, more = _locate(run.obs, run.base, run.context, run.config, run.groups)
    run.notes += more
    if int(run.train.sum()) < SPARSE_WINDOWS:  # a few events: no residual test has the power to gate
        seen = {(p.candidate, p.group) for p in run.proposals}
        extra = [p for p in default_proposals(run.groups) if (p.candidate, p.group) not in seen]
        run.proposals += [replace(p, reason=f"{p.reason}: {int(run.train.sum())} training windows (sparse records) "
                                  "are too few for the residual analysis to gate the candidates") for p in extra]
        if extra:
            run.notes.append(f"{int(run.train.sum())} training windows (sparse records): every candidate is tried "
                             "on its default groups as well as where the residual analysis points")
    info = shipped_threshold()
    run.threshold = float(run.config.threshold if run.config.threshold is not None else info["log_bayes_factor"])
    if run.config.threshold is not None:
        info = {**info, "log_bayes_factor": run.threshold, "provisional": False, "note": "set in the configuration"}
    run.threshold_info = info


def _fit(run: Run) -> None:
    """Every proposal fitted with its evidence; a named numerical failure fails that candidate only."""
    config = run.config
    for i, p in enumerate(run.proposals):
        run.say(f"fit {p.candidate} on {p.group}", (i + 0.5) / max(len(run.proposals), 1))
        ctx = Context(run.context.times_s, run.context.covariates, run.context.start_epoch_s, dict(p.hints))
        cand = CANDIDATES.get(p.candidate)(p.group, ctx)
        job = Job(cand, run.sur, run.lik, run.train)
        try:
            with numerical(cand.label):
                fr = fit(job.gain, job.specs, seed=config.seed + i, n_is=config.n_importance,
                         sensitivity=config.prior_sensitivity)
                res = result(job, fr, run.r_all, run.train, run.epoch, run.z_all)
        except NumericalFailure as exc:  # named numerical failures only: the candidate failed, the run goes on
            run.failed.append(failed_result(cand.vocabulary, cand.label, cand.group, exc, cand.explanation))
            run.notes.append(f"{cand.label}: {run.failed[-1].reasons[0]}")
            continue
        res.extra["proposal_reason"] = p.reason
        spec_key = next(s for s in job.specs if s.name == cand.key_parameter())
        run.keys[res.label] = (spec_key.name, spec_key.null)
        if config.surrogate_check:
            mod = cand.modify(fr.theta_map[None])
            if mod.groups:
                res.extra["surrogate_error"] = run.sur.check(mod)
                if res.extra["surrogate_error"] > config.surrogate_tolerance:
                    run.notes.append(f"{res.label}: surrogate frequency error {res.extra['surrogate_error']:.1e} "
                                     f"exceeds {config.surrogate_tolerance:.0e}")
        form = res.extra.get("form_gain")
        res.form_fits = None if form is None else bool(form <= run.threshold)
        run.tried.append(res)
        run.jobs[res.label] = (job, fr)


def _decide(run: Run) -> None:
    """Acceptance (threshold, held out, interval), ties broken by the shapes, the second estimator."""
    config = run.config
    accepted = decide(run.tried, run.keys, run.threshold, run.held_before, None, config.tie_nats, config.tie_fraction)
    run.accepted = _shape_tiebreak(accepted, run.jobs, run.sur, run.obs, run.kept, run.train, config.tie_nats)
    if config.nested_check:  # the second, independent estimator for every accepted candidate
        for i, c in enumerate(run.accepted):
            run.say(f"evidence check of {c.label}", 0.95)
            job = run.jobs[c.label][0]
            chk, err, method = evidence_check(job.gain, Box(job.specs), config.n_live, config.seed + i,
                                              run.jobs[c.label][1].theta_map)
            c.log_evidence_gain_check = chk - job.cand.look_elsewhere()
            c.extra.update({"check_method": method, "check_err": err})
            tol = max(0.5, 3.0 * math.hypot(c.log_evidence_gain_err, err))
            c.extra["check_agrees"] = bool(abs(c.log_evidence_gain_check - c.log_evidence_gain) <= tol)
            if not c.extra["check_agrees"]:
                run.notes.append(f"{c.label}: the two evidence estimators differ by "
                                 f"{abs(c.log_evidence_gain_check - c.log_evidence_gain):.2f} nats (> {tol:.2f})")
    run.fit_after, run.held_after = run.fit_before, run.held_before
    if run.accepted:
        first = run.accepted[0]
        run.fit_after = first.fit_after or run.fit_before
        run.held_after = first.held_out_after or run.held_before
        run.last = (run.jobs[first.label][0], run.jobs[first.label][1].theta_map)
        run.chain = [first]
        run.fixed = [(run.last[0].cand, run.last[1])]


def _second_round(run: Run) -> None:
    """More effects fitted on top of the accepted one (:func:`.rounds.more_effects`)."""
    if not (run.accepted and run.config.second_round):
        return
    more, run.fit_after, run.held_after, more_last, run.fixed = more_effects(
        run.accepted, run.tried, run.jobs, run.proposals, run.context, run.sur, run.lik, run.train, run.r_all,
        run.epoch, run.threshold, run.config, run.say, run.z_all, run.obs, run.kept)
    run.accepted += more
    run.chain += more
    run.last = more_last or run.last


def _final_estimates(run: Run) -> None:
    """The accepted effects' parameters re-estimated on every window (:func:`.rounds.final_estimates`)."""
    if not run.chain:
        return
    config = run.config
    run.say("final estimates on every window", 0.97)
    lik_all = CandidateLikelihood(run.r_all, run.J, run.rd_all, tau=config.effect_form_error,
                                  noise_guess=config.noise_guess, damping_noise_guess=config.damping_noise_guess,
                                  timing=_timing(run, np.ones(len(run.times_s), bool)))
    twins = [(c, run.jobs[c.label][0].cand, run.jobs[c.label][1].theta_map) for c in run.accepted
             if all(c is not x for x in run.chain) and c.label in run.jobs]
    final = list(run.fixed)
    final_estimates(run.chain, final, twins, run.sur, lik_all, run.epoch, config)
    run.form_of = final[-1]  # the figure of the fitted form shows the reported estimates


def _catch_all(run: Run) -> None:
    """A smooth function of the covariates and time per mode: structure no named effect explains; when
    it beats the named effects together they are downgraded."""
    if not run.config.catch_all:
        return
    threshold, accepted = run.threshold, run.accepted
    basis, names = catch_all_basis(run.context)
    per_mode, fitted = catch_all_gain(run.r_all[run.train], basis[run.train], run.config.noise_guess,
                                      timing=_timing(run, run.train))
    run.catch = catch = float(per_mode.sum())
    # the named model: the accepted effects together (each one's gain is over those before it)
    best_named = (sum(c.log_evidence_gain for c in [accepted[0], *accepted[1 + len(accepted[0].tied_with):]])
                  if accepted else max((c.log_evidence_gain for c in run.tried), default=-math.inf))
    if not (catch > threshold and catch > best_named):
        return
    strong = [run.base.mode_numbers[k] for k in np.argsort(per_mode)[::-1] if per_mode[k] > threshold]
    amp = np.nanmax(np.abs(fitted), axis=1)
    tt = run.times_s[run.train]
    hot = tt[amp >= np.nanquantile(amp, 0.9)] if np.isfinite(amp).any() else tt
    when = [iso_time(run.epoch, float(x)) if run.epoch else float(x) for x in (hot.min(), hot.max())]
    run.unexplained = {"modes": strong, "log_evidence_gain": catch, "best_named_gain": best_named,
                       "when": {"from": when[0], "to": when[1]}, "basis": names,
                       "summary": (f"structured misfit in modes {strong} that no candidate explains (smooth "
                                   f"function of covariates and time: {catch:.1f} nats vs best named "
                                   f"{best_named:.1f})")}
    if accepted:
        # the named effects stay listed (each beat the nominal model on its own terms) but are downgraded:
        # structure remains which they do not explain, and a smooth function of the covariates and time
        # explains it better than they do together; a downgraded effect is not a confident name
        run.unexplained["summary"] += "; the accepted effects explain part of it"
        for c in accepted:
            c.downgraded_by = "catch_all"
            c.reasons.append(f"downgraded: a smooth function of the covariates and time per mode (the catch-all, "
                             f"{catch:.1f} nats) fits better than the named effects together")


def _unmodelled(run: Run) -> None:
    """Observed modes no model mode pairs with, seen in enough windows (the others said in a note)."""
    for u in run.base.unpaired:
        frac = u.get("fraction_of_windows")
        if frac is not None and frac < run.config.min_unpaired_fraction:
            run.notes.append(f"observed mode {u.get('mode')} at {u['frequency_hz']:.3f} Hz could not be paired with a "
                             f"model mode ({u.get('reason')}); seen in {frac:.0%} of the windows, too few to call it "
                             "unmodelled")
            continue
        run.accepted.append(CandidateResult(
            name="unmodelled_modes", label=f"unmodelled_modes/mode{u.get('mode')}", form="a mode the model class lacks",
            where=f"observed mode {u.get('mode')} at {u['frequency_hz']:.3f} Hz", parameters={}, intervals={},
            log_evidence_gain=0.0, log_evidence_gain_check=None, log_evidence_gain_err=0.0, prior_sensitivity={},
            accepted=True, reasons=[f"no model mode pairs with it ({u.get('reason')})"],
            explanation="The structure has a mode the model cannot have (e.g. a lateral or torsional mode of "
                        "a plane model): the model class, not its parameters, is incomplete.",
            extra={"unmodelled": u}))


def _verdict(run: Run) -> Verdict:
    """Figures' numbers, whiteness of what remains (and its downgrade), the fit ratio: the verdict."""
    figures = _series(run.obs, run.base, run.context, run.train, run.r_all, run.z_all, run.last, run.epoch,
                      run.form_of)
    modes = run.base.mode_numbers
    whiteness = residual_whiteness(figures["log_residual_before"], figures["log_residual_after"], modes)
    if run.chain and (left := whiteness.note()):
        run.notes.append(left)
    _whiteness_downgrade(run.accepted, whiteness if run.chain else None, modes)
    ratio = combined(_modal_ratio(run.r_all, run.J, run.context, run.last, run.chain, modes))
    run.say("done", 1.0)
    assert run.fit_after is not None and run.held_after is not None
    return Verdict(mismatch=run.mismatch, missing_physics=run.accepted, tried=run.tried + run.failed,
                   fit_before=run.fit_before, fit_after=run.fit_after, held_out_before=run.held_before,
                   held_out_after=run.held_after, unexplained=run.unexplained, scatter=run.noise,
                   threshold={**run.threshold_info, "catch_all_gain": run.catch}, notes=run.notes,
                   figures=figures, whiteness=whiteness, fit_ratio=ratio[0], fit_ratio_details=ratio[1])


def _whiteness_downgrade(accepted: list[CandidateResult], whiteness, mode_numbers: list[int]) -> None:
    """A named effect is downgraded by the whiteness check when the mode it moves most still follows a
    course in time after the accepted effects that they did not even halve
    (:meth:`.whiteness.Whiteness.unexplained_course`): it does not explain what it claims to."""
    course = [] if whiteness is None else whiteness.unexplained_course()
    for c in accepted:
        delta = c.extra.get("delta")
        if not course or c.downgraded_by is not None or delta is None:
            continue
        main = mode_numbers[int(np.nanargmax(np.nanstd(delta, axis=0)))]
        if main in course:
            c.downgraded_by = "whiteness"
            c.reasons.append(f"downgraded: mode {main}, which it moves most, still follows a course in time after "
                             "the accepted effects, which they did not even halve")


def _modal_ratio(r_all, J, context, last, chain, mode_numbers):
    """The fit ratio after the accepted effects (:mod:`.fit_ratio`): the misfit of the model re-calibrated
    with them (the nominal parameters' linearised shift that best fits the mean misfit, as the
    likelihood's mean part), per mode over its scatter."""
    r = np.array(r_all, float)
    if last is not None:
        d, _ = last[0].deltas(last[1])
        if d is not None:
            r = r - d[0]
    mean = np.nanmean(r, axis=0)
    if J.size and np.isfinite(mean).all():
        shift, *_ = np.linalg.lstsq(J, mean, rcond=None)
        r = r - (J @ shift)[None]
    amp = next((context.covariates[k] for k in ("rms_accel_m_s2", "pga_m_s2") if k in context.covariates), None)
    steps = [int(c.extra["change_window"]) for c in chain if "change_window" in c.extra]
    return modal_fit_ratio(r, list(mode_numbers), amp, steps)


def _series(obs, base, context, train, r_all, z_all, last, epoch, form_of) -> dict:
    """The numbers behind the report's figures (explain_series.json): per window the times, the
    covariates and the misfit before and after the accepted effects (each mode's offset taken out on
    the training windows), the training mask, and the fitted form of the latest accepted effect.
    The misfit after is that of the effects fitted on the training windows (``last``), so that the
    held-out windows' panel stays a test; the form is drawn at the reported estimates (``form_of``,
    fitted on every window)."""
    d = dd = None
    if last is not None:
        job, theta = last
        dd_, ddd = job.deltas(theta)
        d = None if dd_ is None else dd_[0]
        dd = None if ddd is None else ddd[0]
    before = r_all - np.nanmean(r_all[train], axis=0)
    after = r_all if d is None else r_all - d
    after = after - np.nanmean(after[train], axis=0)
    out = {"times_s": np.asarray(obs.times, float), "start_epoch_s": epoch, "mode_numbers": list(base.mode_numbers),
           "model_modes": [i + 1 for i in base.model_index], "covariates": dict(context.covariates),
           "train": train, "log_residual_before": before, "log_residual_after": after,
           "baseline_theta": base.theta}
    if z_all is not None:
        lz = np.log(np.where(z_all > 0, z_all, np.nan))
        out["log_damping_before"] = lz - np.nanmean(lz[train], axis=0)
        la = lz if dd is None else lz - dd
        out["log_damping_after"] = la - np.nanmean(la[train], axis=0)
    if form_of is None and last is not None:
        form_of = (last[0].cand, last[1])
    if form_of is not None:
        out["form"] = _form_curve(form_of[0], form_of[1], context)
    return out


def _form_curve(cand, theta, context) -> dict:
    """The fitted effect against what it depends on: each group's factor (or the damping factor)
    per window, against temperature, amplitude or time, whichever the effect follows."""
    mod = cand.modify(np.atleast_2d(theta))
    base = getattr(cand, "new", cand)
    key = next((k for k in ("temperature_c", "rms_accel_m_s2", "pga_m_s2")
                if k in context.covariates and k.split("_")[0] in type(base).__name__.lower() + base.name), None)
    if key is None and "temperature" in base.name:
        key = "temperature_c"
    if key is None and "amplitude" in base.name:
        key = "rms_accel_m_s2" if "rms_accel_m_s2" in context.covariates else None
    x = np.asarray(context.covariates[key], float) if key else np.asarray(context.times_s, float) / 86400.0
    if mod.groups:
        g, f = next(iter(mod.groups.items()))
        y, ylab = np.asarray(f[0], float), f"factor on {g}"
    else:
        y, ylab = np.asarray(mod.damping[0], float), "damping factor"
    order = np.argsort(x)
    return {"x": x[order], "y": y[order], "x_label": key or "days from the first window", "y_label": ylab,
            "title": f"{base.label}: {base.form(theta) if hasattr(base, 'form') else ''}"}
