"""Sparse earthquake records on both paths (docs/explain.md, Sparse earthquake records): the merged
verdict's fit ratio is the larger of the two paths', its names are ordered confident first; the time
path's form flag; the hinted-window look-elsewhere correction of added mass, damper and support steps."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shm_ros.core.explain.candidates._common import hinted_window_look_elsewhere
from shm_ros.core.explain.candidates.added_mass import AddedMass
from shm_ros.core.explain.candidates.base import Context
from shm_ros.core.explain.candidates.damper_stiffness import DamperStiffness
from shm_ros.core.explain.candidates.support_springs import SupportSprings
from shm_ros.core.explain.td_paths import merge_paths, td_form_fits
from shm_ros.core.explain.types import CandidateResult, FitScores, Mismatch, Verdict


def _entry(name: str, gain: float, accepted: bool = True, form_fits: bool | None = None,
           downgraded_by: str | None = None) -> CandidateResult:
    return CandidateResult(name=name, label=f"{name}/x/EI", form="", where="EI", parameters={}, intervals={},
                           log_evidence_gain=gain, log_evidence_gain_check=None, log_evidence_gain_err=0.0,
                           prior_sensitivity={}, accepted=accepted, form_fits=form_fits, downgraded_by=downgraded_by)


def _verdict(named, ratio, path, nrms=None):
    s = FitScores(nrms_pct=nrms) if nrms is not None else FitScores(frequency_rmse_pct=1.0)
    return Verdict(mismatch=Mismatch([], [], {}, ""), missing_physics=named, tried=list(named), fit_before=s,
                   fit_after=s, held_out_before=s, held_out_after=s, fit_ratio=ratio,
                   fit_ratio_details={path: {"path": path, "ratio": ratio}})


def test_merge_takes_the_larger_ratio_and_orders_confident_names_first():
    modal = _verdict([_entry("stiffness_change_at_time", 9.0, form_fits=False),
                      _entry("unmodelled_modes", 0.0)], 2.0, "modes")
    events = _verdict([_entry("amplitude_dependent_stiffness", 400.0, form_fits=True),
                       _entry("stiffness_change_at_time", 50.0)], 7.5, "events", nrms=20.0)
    v = merge_paths(modal, events)
    assert v.fit_ratio == 7.5 and v.model_fits is False
    assert set(v.fit_ratio_details) >= {"modes", "events", "time_domain_scores"}
    assert [c.name for c in v.missing_physics] == ["amplitude_dependent_stiffness", "stiffness_change_at_time",
                                                    "unmodelled_modes"]
    step = v.missing_physics[1]
    assert step.extra["path"] == "modes" and step.extra["time_domain_gain"] == 50.0
    assert v.to_dict()["fit_ratio"] == 7.5
    # the other way round: the modal path's ratio is the larger one
    assert merge_paths(_verdict([], 6.0, "modes"), _verdict([], 1.2, "events", nrms=3.0)).fit_ratio == 6.0


def test_time_path_form_flag():
    amp = np.geomspace(0.05, 2.0, 10)
    rising = 5.0 + 20.0 * amp  # the strong events' misfit left larger: a wrong form
    assert td_form_fits(rising, amp)[0] is False
    rng = np.random.default_rng(1)
    flat = 8.0 + rng.normal(0.0, 0.5, 10) + 4.0 / (1.0 + 10 * amp)  # noise share falling with amplitude
    ok, info = td_form_fits(flat, amp)
    assert ok is True and info["form_rank_correlation"] < 0
    assert td_form_fits(rising[:4], amp[:4])[0] is None  # too few events to judge


@pytest.mark.parametrize("cls,hints", [(AddedMass, {"when": "after"}), (DamperStiffness, {}), (SupportSprings, {})])
def test_hinted_window_pays_the_look_elsewhere_correction(cls, hints):
    W = 12
    ctx = Context(times_s=np.arange(W) * 86400.0, covariates={}, hints={**hints, "change_index": 5})
    cand = cls("mass" if cls is AddedMass else "damper" if cls is DamperStiffness else "bearings", ctx)
    assert cand.look_elsewhere() == pytest.approx(math.log(W - 2))
    span = Context(times_s=ctx.times_s, covariates={}, hints={**hints, "change_index": 5, "change_span": (4, 6)})
    assert hinted_window_look_elsewhere(span) == pytest.approx(math.log((W - 2) / 3))
    free = cls(cand.group, Context(times_s=ctx.times_s, covariates={}, hints={}))
    assert free.look_elsewhere() == 0.0
