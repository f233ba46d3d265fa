"""explain on sparse earthquake records from the independent OpenSeesPy truths, at reduced size (CI):
one development campaign (seed 0, 1-2 stories, 5 events) of every event kind through
``shm-ros explain --bag`` (per-event modal estimates and the time-domain path), judged by the
acceptance rules of bench/explain_acceptance.py (the full size runs there, docs/explain.md).

Thresholds (binomial, a method meeting the acceptance's rates passes with >= 99 %):

* every campaign gives a verdict (exit code 0): deterministic, no margin;
* in-vocabulary kinds (stiffness loss, hysteretic, amplitude damping, soil, damper loss; 5
  campaigns), a confident right name in each with probability >= 0.8 at least: P(X <= 1 | n=5, p=0.8)
  = 0.0067, so >= 2 of 5 passes with 99.3 %;
* a step (``stiffness_change_at_time``) on the clean and the transient-softening campaigns (rates
  <= 1 % and <= 2 %): P(X >= 2 | n=2, p=0.02) = 0.0004, so at most 1 of 2 passes with 99.96 %;
* breathing crack (outside the vocabulary, >= 90 % acceptable): P(X = 0 | n=1, p=0.9) = 0.1 > 1 %,
  so one campaign cannot be judged at 99 %; it is run (a verdict) and not counted.

The in-vocabulary count is met on seed 0 since the time path gives each event its own error variance and
holds out the second strongest event (2 of 5: the stiffness loss and the amplitude damping; before, the
stiffness loss alone, and the test was an expected failure). Development figures over seeds 0-3
(docs/explain.md, "Input-driven modes"): stiffness loss 4/4, amplitude damping 4/4, damper loss 3/4,
hysteretic 2/4, soil 0/4 (13 of 20: a per-campaign rate of 0.65, below the acceptance's 0.8).
"""

from __future__ import annotations

import multiprocessing as mp
import os

import pytest

from bench.explain_acceptance import _nice, run_one

IN_VOCABULARY = {"stiffness_loss": "event_stiffness_loss", "hysteretic": "event_hysteretic",
                 "amplitude_damping": "event_amplitude_damping", "soil": "event_soil",
                 "damper_loss": "event_damper_loss"}
NO_STEP = {"nulls": "event_clean", "transient_or_lagged": "event_transient_softening"}
OUTSIDE = {"breathing_crack": "event_breathing_crack"}


@pytest.fixture(scope="module")
def results() -> dict[str, dict]:
    tasks = [(row, kind, 0, "reduced") for row, kind in {**IN_VOCABULARY, **NO_STEP, **OUTSIDE}.items()]
    jobs = 1 if os.environ.get("PYTEST_XDIST_WORKER") else 2  # under xdist the other worker has the other core
    with mp.get_context("spawn").Pool(jobs, initializer=_nice) as pool:
        return {r["kind"]: r for r in pool.map(run_one, tasks)}


def test_every_sparse_campaign_gets_a_verdict(results):
    bad = {k: r.get("error") for k, r in results.items() if "error" in r}
    assert not bad, bad


def test_no_step_on_clean_or_transient_softening(results):
    steps = [k for k in NO_STEP.values() if results[k].get("step")]
    assert len(steps) <= 1, steps


def test_in_vocabulary_sparse_kinds_are_named(results):
    right = [k for k in IN_VOCABULARY.values() if results[k].get("ok")]
    assert len(right) >= 2, {k: results[k].get("names") for k in IN_VOCABULARY.values()}


def test_the_judge_takes_a_whole_structure_step_only_when_every_story_was_damaged():
    from bench.explain_acceptance import _where_right

    two = {"building": {"stories": 2}, "effect": {"magnitudes": {"stories": [0, 1]}}}
    one = {"building": {"stories": 2}, "effect": {"magnitudes": {"stories": [1]}}}
    assert _where_right("EI", two) and not _where_right("EI", one)
    assert _where_right("EI:2", one) and not _where_right("EI:1", one) and _where_right("EI:1,EI:2", one)
