"""Sparse earthquake records on both paths: the per-event modal verdict and the time-domain verdict as
one (docs/explain.md, Sparse earthquake records).

A recording of a few events with a measured input is explained twice: per event as modal estimates
with their amplitude covariates (:func:`.explain.explain`: a stiffness lost between two events, a
damper lost, supports; what frequencies show) and in the time domain (:func:`.timedomain.explain_events`:
stiffness and damping that change with the amplitude within and between events; what the records
show beyond the frequencies). :func:`merge_paths` makes one verdict of the two:

* the named effects of both, confident ones first (accepted, form not seen to fail, not downgraded),
  within each rank the modal path's before the time path's, the unmodelled modes last; an effect both
  paths name is listed once (the modal entry, with the time path's gain in ``extra``);
* the fit ratio is the larger of the two paths' ratios (docs/interfaces.md §5), both kept in
  ``fit.fit_ratio``;
* the fit scores, scatter, whiteness and figures are the modal path's; the time path's NRMS before
  and after are kept in ``fit.fit_ratio.time_domain_scores``, its threshold under
  ``threshold.time_domain``, its notes among the notes.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy.stats import spearmanr

from .fit_ratio import combined
from .types import CandidateResult, Verdict

FORM_P = 0.01  # one-sided level of the time path's form check (misfit still growing with amplitude)
MIN_FORM_EVENTS = 5  # fewer events: no form to test (form_fits None)


def td_form_fits(nrms_after: np.ndarray, amplitude: np.ndarray) -> tuple[bool | None, dict]:
    """The time path's form flag: after a candidate whose form fits, what it leaves no longer grows
    with the events' amplitude (the noise's share of the NRMS falls with it, the model-form error's
    share is the same at every amplitude); a wrong form (a softening law fitted to a friction, a
    stiffness law to a damping effect) leaves the strong events' misfit larger. Test: Spearman's rank
    correlation of the per-event NRMS after the candidate with the amplitude, one-sided at
    :data:`FORM_P`: a significant rise says ``form_fits: false``. None with fewer than
    :data:`MIN_FORM_EVENTS` events."""
    y, a = np.asarray(nrms_after, float), np.asarray(amplitude, float)
    ok = np.isfinite(y) & np.isfinite(a)
    if ok.sum() < MIN_FORM_EVENTS or np.ptp(a[ok]) == 0 or np.ptp(y[ok]) == 0:
        return None, {}
    rho, p = spearmanr(a[ok], y[ok])
    p_one = float(p) / 2 if rho > 0 else 1.0 - float(p) / 2
    return bool(p_one >= FORM_P), {"form_rank_correlation": float(rho), "form_p_value": p_one}


def _rank(c: CandidateResult) -> int:
    if c.name == "unmodelled_modes":
        return 2
    return 0 if c.confident else 1


def merge_paths(modal: Verdict, events: Verdict) -> Verdict:
    """One verdict of the modal and the time-domain verdicts of the same events (module docstring)."""
    named = {c.name: c for c in modal.missing_physics}
    extra_td = []
    for c in events.missing_physics:
        c.extra["path"] = "time_domain"
        if c.name in named:
            named[c.name].extra["time_domain_gain"] = float(c.log_evidence_gain)
        else:
            extra_td.append(c)
    for c in modal.missing_physics:
        c.extra.setdefault("path", "modes")
    listed = [*modal.missing_physics, *extra_td]
    order = sorted(range(len(listed)), key=lambda i: (_rank(listed[i]), i))
    modal_part = {**modal.fit_ratio_details.get("modes", {"path": "modes"})}
    events_part = {**events.fit_ratio_details.get("events", {"path": "events"})}
    ratio = combined((modal_part.pop("ratio", modal.fit_ratio), modal_part),
                     (events_part.pop("ratio", events.fit_ratio), events_part))
    notes = [*modal.notes, *(f"time domain: {n}" if not n.startswith("time domain") else n for n in events.notes)]
    fr = ratio[0]
    return replace(modal, missing_physics=[listed[i] for i in order], tried=[*modal.tried, *events.tried],
                   threshold={**modal.threshold, "time_domain": dict(events.threshold)}, notes=notes,
                   fit_ratio=None if fr is None or not math.isfinite(fr) else fr,
                   fit_ratio_details={**ratio[1], "time_domain_scores": {
                       "before": events.fit_before.to_dict(), "after": events.fit_after.to_dict(),
                       "held_out_before": events.held_out_before.to_dict(),
                       "held_out_after": events.held_out_after.to_dict()}})
