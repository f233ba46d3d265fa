"""Which fitted candidates explain the data: threshold, held-out windows, null excluded, ties, catch-all.

A candidate is accepted when all three hold:

1. its evidence gain over the nominal model clears the **threshold**: the 99th percentile of the
   largest gain over all candidates on clean replicates (no effect, the simulator's default model-form
   error), calibrated once offline by ``bench/calibrate_explain.py`` and shipped as
   ``threshold.json`` next to this module (``provisional`` there until the calibration has run);
2. the frequency misfit on the **held-out windows** (never used in the fit) is smaller with it; for an
   effect that starts at a moment (a change time) the training windows place only within a held-out
   block, on the other held-out windows, with it and without it alike (:func:`held_out_pair`);
3. the 95 % interval of its **key parameter** excludes the value at which it is the nominal model.

Accepted candidates within ``tie_nats`` of the most supported one, or whose best fits are within
``tie_nats`` of its best fit (the data cannot tell them apart; their evidences then differ by prior
volume only), are reported together
(``tied_with``, with their relative support ``exp(gain)`` normalised over the tied set): the data
cannot tell them apart. The **catch-all** (a smooth function of the covariates and of time per mode,
:func:`.likelihood.catch_all_gain`) is compared in :mod:`.explain` with the accepted effects together:
when it beats them, ``unexplained`` says where (modes) and when structure remains that they do not
explain. ``decide`` is called without it (``catch_all=None``); given one, it still vetoes every
candidate it beats.
"""

from __future__ import annotations

import json
import math
from importlib import resources
from typing import Any

import numpy as np

from .types import CandidateResult, FitScores

THRESHOLD_FILE = "threshold.json"


def shipped_threshold(name: str = THRESHOLD_FILE) -> dict[str, Any]:
    """The calibrated acceptance threshold shipped with the package (``threshold.json``; the
    time-domain path's in ``threshold_timedomain.json``)."""
    text = resources.files("shm_ros.core.explain").joinpath(name).read_text()
    return dict(json.loads(text))


def null_excluded(c: CandidateResult, key: str, null: float | None) -> bool:
    if null is None or key not in c.intervals:
        return True
    lo, hi = c.intervals[key]
    return not lo <= null <= hi


def held_out_metric(c: CandidateResult) -> str:
    """What the held-out windows are scored on: damping RMSE for a candidate that changes the modal
    damping only, frequency RMSE otherwise; a candidate may name its own (time domain: ``nrms_pct``)."""
    if c.extra.get("held_out_metric"):
        return str(c.extra["held_out_metric"])
    return "damping_rmse_pct" if c.extra.get("acts_on") == "damping" else "frequency_rmse_pct"


def held_out_pair(c: CandidateResult, reference: FitScores) -> tuple[str, float, float, str]:
    """The held-out check's metric, the candidate's score and the score without it (``reference``:
    the nominal model's, or the effects' it is fitted on top of), and where. A candidate that starts
    at a moment the training windows cannot place among some held-out windows (``extra
    ["held_out_check"]``, :func:`.jobs.held_out_check`) is judged, and its reference with it, on the
    other held-out windows alone; so is one fitted on top of such a change (:func:`.jobs.judged_on`)."""
    metric = held_out_metric(c)
    chk = c.extra.get("held_out_check")
    after, before = (chk["after"], chk["before"]) if chk else (c.held_out_after, reference)
    held = getattr(after, metric) if after is not None else None
    ref = getattr(before, metric)
    where = ""
    if chk:
        a, b = chk["left_out"]
        where = (f" on {chk['windows']} of {chk['of']} held-out windows (windows {a}-{b}, among which the training "
                 f"windows cannot place {chk.get('starts') or 'its start'}, left out)")
    return metric, math.inf if held is None else held, math.inf if ref is None else ref, where


def decide(results: list[CandidateResult], keys: dict[str, tuple[str, float | None]], threshold: float,
           held_out_before: FitScores, catch_all: float | None, tie_nats: float,
           tie_fraction: float = 0.0, tie_corr: float = 0.95) -> list[CandidateResult]:
    """Mark ``accepted`` and ``reasons`` on every result; the accepted ones, most supported first.

    ``keys[label] = (key parameter, null value)``; ``held_out_before``: the nominal model's scores on
    the held-out windows; ``catch_all``: the catch-all's gain (None: not fitted).
    """
    for c in results:
        key, null = keys[c.label]
        metric, held, before, where = held_out_pair(c, held_out_before)
        checks = [
            (c.log_evidence_gain > threshold,
             f"evidence gain {c.log_evidence_gain:.1f} nats vs threshold {threshold:.1f}"),
            (held < before,
             f"held-out {metric.replace('_rmse_pct', ' RMSE').replace('_pct', '')} {held:.3f} % vs {before:.3f} % "
             "without it" + where),
            (null_excluded(c, key, null),
             f"95 % interval of {key} {_iv(c.intervals.get(key))} "
             + ("excludes" if null_excluded(c, key, null) else "includes") + f" the null value {null}"),
        ]
        c.accepted = all(ok for ok, _ in checks)
        c.reasons = [("passed: " if ok else "failed: ") + why for ok, why in checks]
    passing = sorted((c for c in results if c.accepted), key=lambda c: -c.log_evidence_gain)
    if catch_all is not None and (not results or catch_all > max(c.log_evidence_gain for c in results)):
        for c in passing:
            c.accepted = False
            c.reasons.append(f"failed: a smooth function of the covariates per mode (the catch-all, gain "
                             f"{catch_all:.1f} nats) fits better than every named candidate")
        return []
    if not passing:
        return []
    best = passing[0]
    # the data cannot tell two candidates apart when their best fits are equally good (e.g. a uniform
    # added mass and a uniform stiffness loss move every frequency alike): their evidences then differ
    # only by their priors' volumes, which is no reason to name one of them
    # nor when both say the same thing happened at the same times and differ only in how much each
    # mode moved, by little evidence (_alike): e.g. a step in uniform mass or in the deck's
    # stiffness, which model-form error in the bearings can make the data prefer either way
    tied = [c for c in passing if best.log_evidence_gain - c.log_evidence_gain <= tie_nats
            or abs(_fit_gain(best) - _fit_gain(c)) <= tie_nats or _alike(best, c, tie_corr, tie_fraction)]
    z = [math.exp(c.log_evidence_gain - best.log_evidence_gain) for c in tied]
    for c, zi in zip(tied, z, strict=True):
        c.tied_with = [o.label for o in tied if o is not c]
        c.extra["relative_support"] = zi / sum(z)
    for c in [c for c in passing if c not in tied]:
        c.accepted = False
        c.reasons.append(f"failed: {best.label} explains the same misfit better "
                         f"({best.log_evidence_gain - c.log_evidence_gain:.1f} nats)")
    return tied


def _fit_gain(c: CandidateResult) -> float:
    return float(c.extra.get("gain_at_map", c.log_evidence_gain))


def _iv(iv: tuple[float, float] | None) -> str:
    return "n/a" if iv is None else f"[{iv[0]:.4g}, {iv[1]:.4g}]"


def _alike(a: CandidateResult, b: CandidateResult, min_corr: float, fraction: float) -> bool:
    """The two fits say the same thing happened at the same times: their changes of ln f over the
    training windows (``extra["delta"]``) correlate at ``min_corr`` or more, mode by mode, on average
    weighted by how much each mode moves in both (the product of the two changes' norms), so they
    differ only in how much each mode moves (the pattern that the analysis model's model-form error
    distorts: locate allows it 15 %); and their evidences differ by at most ``fraction`` of the best's
    gain (on many windows a pattern distortion of that kind still adds up to nats). The weighting: a
    mode that one of the fits barely moves holds little of its course in time, and the surrogate's
    second-order terms (mode veering) bend it; asking every moving mode to correlate let such a mode
    decide (a freezing knee of one span and of the whole deck, 0.997-1.000 in the four modes they
    move most and 0.91 in the fifth, which the span's knee moves by a fifth of its largest change,
    were not tied, and the deck's knee won by 4 nats of 938)."""
    da, db = a.extra.get("delta"), b.extra.get("delta")
    if fraction <= 0 or da is None or db is None or np.shape(da) != np.shape(db):
        return False
    fitted = a.extra.get("fitted_windows")
    if fitted is not None and np.shape(fitted) == np.shape(da)[:1]:
        # compared where they were fitted: on held-out windows two fits may place a change the training
        # windows cannot place (within a held-out block) at different points, which says nothing
        da, db = np.asarray(da)[fitted], np.asarray(db)[fitted]
    if a.log_evidence_gain - b.log_evidence_gain > fraction * abs(a.log_evidence_gain):
        return False
    da = np.asarray(da, float) - np.nanmean(da, axis=0)
    db = np.asarray(db, float) - np.nanmean(db, axis=0)
    na, nb = np.sqrt(np.nansum(da ** 2, axis=0)), np.sqrt(np.nansum(db ** 2, axis=0))
    moving = (na > 1e-3 * na.max()) & (nb > 1e-3 * nb.max()) if na.max() > 0 and nb.max() > 0 else na > 0
    if not np.any(moving):
        return False
    corr = np.nansum(da * db, axis=0)[moving] / (na[moving] * nb[moving])
    weight = (na * nb)[moving]
    return bool(np.sum(weight * corr) >= min_corr * np.sum(weight))
