"""explain on cases it was not built for: the effect, where it acts and its size drawn at random
(test/explain_cases.py) on the simulator's default model-form error (the truth is outside the
analysis model's class: per-mode offsets no parameter explains, out-of-plane modes among the tracked
ones), scored by test/explain_scoring.py against the truth.

Full size (``SHM_FULL=1``): 5 cases per vocabulary name (40), 864 windows each; 50 clean seeds;
15 cases of two effects. Criteria (docs/explain.md): the right top name in >= 90 % overall and >= 60 %
per name, and among those every parameter / fit check in >= 90 %; no false alarm in >= 95 % of the
clean seeds; both effects with every check in >= 13 of 15 two-effect cases.

Reduced size (CI): one case per name (8) at 192 windows, 6 clean seeds, one two-effect case, with
thresholds that a method meeting the full-size rates passes with >= 99 % probability:
* named cases: a case counts when its top name and all its checks hold; with the per-case rate of the
  latest full-size run (37/40 = 0.925 right with every check, docs/explain.md),
  P(at least 5 of 8) = 0.998 (at least 6 of 8, the threshold derived from the earlier 38/40, would
  hold with 0.982 only);
* clean: the threshold is the 99th percentile of the largest gain on clean replicates, so the per-seed
  false-alarm rate is about 1 %: P(at most 1 of 6) = 0.9985 (0/50 false alarms at full size);
* the two-effect case and the unmodelled-modes case are exact checks (both effects found; the listed
  modes equal the out-of-plane modes) on fixed seeds: the unmodelled modes were listed exactly on
  every full-size seed; the two-effect cases meet every criterion on 14 of 15 full-size seeds (seed
  12 misses the slope below the knee), so seed 0's check guards against a regression of
  its own case rather than being a 1 % check.
Every accepted candidate's evidence is checked against the second estimator (nested sampling) within
max(0.5, 3 combined standard errors).
"""

from __future__ import annotations

import math
import os
import re
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest
from explain_cases import draw_case
from explain_scoring import parameter_checks, score, top_entry, truth_misfit

from shm_ros.core.explain.explain import explain
from shm_ros.core.structure import structure_from_dict

FULL = os.environ.get("SHM_FULL", "") not in ("", "0")
NAMES = ("temperature_dependent_stiffness", "amplitude_dependent_stiffness", "amplitude_dependent_damping",
         "added_mass", "support_flexibility", "stiffness_change_at_time", "damper_stiffness", "unmodelled_modes")
PER_NAME = 5 if FULL else 1
WINDOWS = 864 if FULL else 192
CLEAN_SEEDS = 50 if FULL else 6
TWO = 15 if FULL else 1


def _run(case):
    v = explain(case.obs, structure_from_dict(case.structure))
    return v, v.to_dict()


def _check_evidence(d):
    for c in d["candidates"]:
        if not c["accepted"] or c.get("log_evidence_gain_check") is None:
            continue
        se = math.hypot(c["log_evidence_gain_err"] or 0.0, c.get("log_evidence_gain_check_err") or 0.0)
        gap = abs(c["log_evidence_gain_check"] - c["log_evidence_gain"])
        assert gap <= max(0.5, 3 * se), (c["label"], c["log_evidence_gain"], c["log_evidence_gain_check"], se)


DOC_TALLIES = {  # where docs/explain.md quotes the full-size tallies (whitespace normalised)
    "top": r"\| right top name, 40 cases \(5 per vocabulary name\) \| (\d+/\d+) ",
    "alarms": r"\| clean tables, 50 seeds \| (\d+) false alarms",
    "every_check": r"full-size rates \((\d+/\d+) right with every check; ",
    "alarm_rate": r"right with every check; (\d+/\d+), the calibrated threshold's 1 %\)",
}


def documented_tallies() -> dict[str, str]:
    """The full-size tallies as docs/explain.md quotes them (test_documented_results.py checks them against
    docs/results/full_size.json, which ``SHM_FULL=1`` writes)."""
    text = " ".join((Path(__file__).resolve().parents[1] / "docs" / "explain.md").read_text().split())
    found = {k: re.search(p, text) for k, p in DOC_TALLIES.items()}
    missing = [k for k, m in found.items() if m is None]
    assert not missing, f"docs/explain.md no longer quotes {missing} where DOC_TALLIES looks"
    return {k: m.group(1) for k, m in found.items() if m is not None}


def record_tallies(figures: dict[str, str]) -> None:
    """This full-size run's tallies into docs/results/full_size.json (the two tests write their halves)."""
    from full_size_results import record, recorded

    mine = recorded().get("explain_acceptance", {}).get("figures", {})
    record("explain_acceptance", {**mine, **figures},
           "SHM_FULL=1 python -m pytest -n 2 -rA test/test_explain_acceptance.py")


def test_documented_tallies_are_found():
    doc = documented_tallies()
    assert all(doc.values()), doc


def test_named_effects_found_and_fitted():
    results = []
    for i, name in enumerate(NAMES):
        for j in range(PER_NAME):
            case = draw_case(7000 + 100 * i + j, name, n_windows=WINDOWS)
            v, d = _run(case)
            _check_evidence(d)
            results.append(score(d, case, v.figures))
    lines = [f"{s.name}: top {s.top} {s.checks} {s.details.get('listed', '')}" for s in results]
    report = "\n".join(lines)
    right = [s for s in results if s.top_ok]
    print(f"right top name {len(right)}/{len(results)}; per name "
          + ", ".join(f"{n} {sum(s.top_ok for s in results if s.name == n)}/{sum(s.name == n for s in results)}"
                      for n in NAMES)
          + "; checks " + ", ".join(f"{k} {sum(s.checks[k] for s in right if k in s.checks)}/"
                                   f"{sum(k in s.checks for s in right)}"
                                   for k in sorted({k for s in right for k in s.checks})))
    print(report)
    if FULL:  # the tallies docs/explain.md quotes (test_documented_results.py compares them)
        record_tallies({"top": f"{len(right)}/{len(results)}",
                        "every_check": f"{sum(s.ok for s in results)}/{len(results)}"})
        assert sum(s.top_ok for s in results) >= 0.9 * len(results), report
        for name in NAMES:
            mine = [s for s in results if s.name == name]
            assert sum(s.top_ok for s in mine) >= 0.6 * len(mine), report
        right = [s for s in results if s.top_ok]
        checks = {k for s in right for k in s.checks}
        for k in checks:
            have = [s.checks[k] for s in right if k in s.checks]
            assert sum(have) >= 0.9 * len(have), (k, report)
    else:
        assert sum(s.ok for s in results) >= 5, report


def test_clean_recordings_raise_no_false_alarm():
    alarms, listed_wrong = [], []
    for seed in range(CLEAN_SEEDS):
        case = draw_case(8000 + seed, "clean", n_windows=WINDOWS)
        _, d = _run(case)
        named = [m["name"] for m in d["missing_physics"] if m["name"] != "unmodelled_modes"]
        if named:
            alarms.append((seed, named))
        # a clean table holds the in-plane modes only: nothing to list as unmodelled
        if any(m["name"] == "unmodelled_modes" for m in d["missing_physics"]):
            listed_wrong.append(seed)
    print(f"false alarms {len(alarms)}/{CLEAN_SEEDS}: {alarms}; unmodelled listed on a clean table {listed_wrong}")
    if FULL:  # the tallies docs/explain.md quotes (test_documented_results.py compares them)
        record_tallies({"alarms": str(len(alarms)), "alarm_rate": f"{len(alarms)}/{CLEAN_SEEDS}"})
    assert len(alarms) <= (0.05 * CLEAN_SEEDS if FULL else 1), alarms
    assert len(listed_wrong) <= (0.05 * CLEAN_SEEDS if FULL else 1), listed_wrong


def test_unmodelled_modes_listed_exactly():
    for seed in range(3 if FULL else 1):
        case = draw_case(8500 + seed, "unmodelled_modes", n_windows=WINDOWS)
        _, d = _run(case)
        listed = {int(m["where"].split()[2]) for m in d["missing_physics"] if m["name"] == "unmodelled_modes"}
        assert listed == set(case.truth.out_of_plane_modes), (listed, case.truth.out_of_plane_modes)
        assert top_entry(d) is None, d["missing_physics"]


def _two_effects(seed: int) -> dict[str, bool]:
    """Seed ``9000 + seed`` of the freezing knee and the later loss: each criterion, True or False."""
    case = draw_case(9000 + seed, "temperature_dependent_stiffness", kind="girder", n_windows=WINDOWS,
                     form="bilinear", second_step=True)
    v, d = _run(case)
    _check_evidence(d)
    found = [m for m in d["missing_physics"] if m["name"] != "unmodelled_modes"]
    names = [m["name"] for m in found]
    out = {"both": "temperature_dependent_stiffness" in names and "stiffness_change_at_time" in names}
    if not out["both"]:
        return out
    knee = next(m for m in found if m["name"] == "temperature_dependent_stiffness")
    step = next(m for m in found if m["name"] == "stiffness_change_at_time")
    checks = parameter_checks("temperature_dependent_stiffness", knee, case.truth, case.obs.times)
    out.update(knee=bool(checks.get("knee")), slope=bool(checks.get("slope")),
               time=abs(int(step["change_window"]) - int(case.truth.second.change_index)) <= 6)
    # the fit of both together (not the top entry's name, which may be the step's tied twin)
    b, a = truth_misfit(case, v.figures)
    out["halved"] = b is not None and a is not None and a <= 0.5 * b
    held = d["fit"]["held_out"]
    out["held_out"] = held["after"]["frequency_rmse_pct"] < held["before"]["frequency_rmse_pct"]
    # every refit on top of the first effect is in the table of candidates, the accepted one and the rest
    on_top = [c for c in d["candidates"] if " on top of " in " ".join(c["reasons"])]
    out["listed"] = sum(c["accepted"] for c in on_top) == 1 and len(on_top) >= (1 if FULL else 3)
    return out


@pytest.mark.skipif(FULL, reason="at full size: test_two_effects_over_seeds")
def test_two_effects_a_freezing_knee_and_a_later_stiffness_loss():
    checks = _two_effects(0)
    assert all(checks.values()), checks


@pytest.mark.skipif(not FULL, reason="full size only (SHM_FULL=1)")
def test_two_effects_over_seeds():
    """15 seeds; every criterion in at least 13 (the named cases' 90 % per check, 13.5 of 15, less
    the half case a finite count cannot meet)."""
    with ProcessPoolExecutor(2) as pool:  # the named cases' test runs beside it: two cores in all
        rows = dict(zip(range(TWO), pool.map(_two_effects, range(TWO)), strict=True))
    bad = {seed: [k for k, ok in c.items() if not ok] for seed, c in rows.items() if not all(c.values())}
    print(f"two effects: {TWO - len(bad)}/{TWO} meet every criterion; failures {bad}")
    assert TWO - len(bad) >= 13, bad
