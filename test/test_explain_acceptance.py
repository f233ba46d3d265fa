"""explain on cases it was not built for: the effect, where it acts and its size drawn at random
(test/explain_cases.py) on the simulator's default model-form error (the truth is outside the
analysis model's class: per-mode offsets no parameter explains, out-of-plane modes among the tracked
ones), scored by test/explain_scoring.py against the truth.

Full size (``SHM_FULL=1``): 5 cases per vocabulary name (40), 864 windows each; 50 clean seeds;
15 cases of two effects. Criteria (docs/explain.md): the right top name in >= 90 % overall and >= 60 %
per name, and among those every parameter / fit check in >= 90 %; no false alarm in >= 95 % of the
clean seeds; both effects with every check in >= 13 of 15 two-effect cases.

Reduced size (CI): one case per name (8) at 192 windows, 6 clean seeds, up to three two-effect cases,
with thresholds that a method meeting the measured rates passes with >= 99 % probability:
* named cases: a case counts when its top name and all its checks hold; with the per-case rate of the
  drifting misfit on 40 development cases at this size (37/40 right with every check at d313ab1, 36/40
  at 324a556; seeds 20001-20005, docs/explain.md "Final estimates"), P(at least 5 of 8) = 0.998
  (0.995 at 36/40; at least 6 of 8 would hold with 0.962 only at 36/40);
* clean: the threshold is the 99th percentile of the largest gain on clean replicates, so the per-seed
  false-alarm rate is about 1 %: P(at most 1 of 6) = 0.9985 (0/50 false alarms at full size);
* two-effect cases: up to three, both effects named in at least one (18 of 20 development cases at this
  size name both: P = 1 - (2/20)^3 = 0.999); every criterion together is asserted at full size only
  (at 13 of 15 two reduced cases would pass "at least one" with 0.98 only);
* the unmodelled-modes case is an exact check (the listed modes equal the out-of-plane modes): they
  were listed exactly on every full-size seed.
Seeds: every row's from the git tree of ``shm_ros/core`` (:func:`seeds`, which holds the shipped
threshold files), so the figures come from seeds drawn after the last change of the method and no
seed is chosen; CI takes the first seeds of the same rows. Each full-size run appends its rows'
seeds and figures to docs/results/explain_dense_log.md, and a test checks them against the hash.
Development runs use seeds below ``acceptance_seeds.DEV_SEEDS`` (e.g. 9300-9319 of the two-effect
cases).
Every accepted candidate's evidence is checked against the second estimator (quadrature or nested
sampling) within max(0.5, 3 combined standard errors) (docs/explain.md, "Fit and evidence").
"""

from __future__ import annotations

import math
import os
import re
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest
from acceptance_seeds import DEV_SEEDS, core_tree, explain_seeds
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
TWO_CI = 3
LOG = Path(__file__).resolve().parents[1] / "docs" / "results" / "explain_dense_log.md"


def seeds(row: str, n: int, tree: str | None = None) -> list[int]:
    """``n`` acceptance seeds of one row (``named:<name>``, ``clean``, ``unmodelled``, ``two_effects``) from
    the git tree of ``shm_ros/core`` (which holds the shipped threshold files): drawn by the hash alone
    after the last change of the method, >= ``DEV_SEEDS`` (development seeds are below it); CI takes
    the first ones of the same rows."""
    return explain_seeds(n, core_tree() if tree is None else tree, f"dense_{row}")


def _run(case):
    v = explain(case.obs, structure_from_dict(case.structure))
    return v, v.to_dict()


def _evidence_gaps(d) -> list[str]:
    """Accepted candidates whose two evidence estimators differ by more than max(0.5, 3 standard
    errors): a criterion of every row, logged with its figures before the row asserts (a full-size
    row stopped at its first such case used to leave no line in the log)."""
    out = []
    for c in d["candidates"]:
        if not c["accepted"] or c.get("log_evidence_gain_check") is None:
            continue
        se = math.hypot(c["log_evidence_gain_err"] or 0.0, c.get("log_evidence_gain_check_err") or 0.0)
        gap = abs(c["log_evidence_gain_check"] - c["log_evidence_gain"])
        if gap > max(0.5, 3 * se):
            out.append(f"{c['label']} {c['log_evidence_gain']:.2f} vs {c['log_evidence_gain_check']:.2f} (se {se:.2f})")
    return out


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
    results, gaps = [], []
    for name in NAMES:
        for seed in seeds(f"named:{name}", PER_NAME):
            case = draw_case(seed, name, n_windows=WINDOWS)
            v, d = _run(case)
            gaps += [(name, seed, g) for g in _evidence_gaps(d)]
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
    print(f"evidence estimators disagree: {gaps}")
    if FULL:  # the tallies docs/explain.md quotes (test_documented_results.py compares them)
        record_tallies({"top": f"{len(right)}/{len(results)}",
                        "every_check": f"{sum(s.ok for s in results)}/{len(results)}"})
        for name in NAMES:
            mine = [s for s in results if s.name == name]
            append_log(f"named:{name}", seeds(f"named:{name}", PER_NAME),
                       f"right top name {sum(s.top_ok for s in mine)}/{len(mine)}, every check "
                       f"{sum(s.ok for s in mine)}/{len(mine)}, evidence estimators disagree on "
                       f"{[(seed, g) for n, seed, g in gaps if n == name]}",
                       sum(s.top_ok for s in mine) >= 0.6 * len(mine) and not any(n == name for n, _, _ in gaps))
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
    assert not gaps, gaps


def test_clean_recordings_raise_no_false_alarm():
    alarms, listed_wrong = [], []
    for seed in seeds("clean", CLEAN_SEEDS):
        case = draw_case(seed, "clean", n_windows=WINDOWS)
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
        append_log("clean", seeds("clean", CLEAN_SEEDS), f"false alarms {len(alarms)}/{CLEAN_SEEDS} {alarms}, "
                   f"unmodelled listed on {len(listed_wrong)}", len(alarms) <= 0.05 * CLEAN_SEEDS
                   and len(listed_wrong) <= 0.05 * CLEAN_SEEDS)
    assert len(alarms) <= (0.05 * CLEAN_SEEDS if FULL else 1), alarms
    assert len(listed_wrong) <= (0.05 * CLEAN_SEEDS if FULL else 1), listed_wrong


def test_unmodelled_modes_listed_exactly():
    drawn = seeds("unmodelled", 3 if FULL else 1)
    wrong = []
    for seed in drawn:
        case = draw_case(seed, "unmodelled_modes", n_windows=WINDOWS)
        _, d = _run(case)
        listed = {int(m["where"].split()[2]) for m in d["missing_physics"] if m["name"] == "unmodelled_modes"}
        if listed != set(case.truth.out_of_plane_modes) or top_entry(d) is not None:
            wrong.append((seed, sorted(listed), case.truth.out_of_plane_modes, top_entry(d)))
    if FULL:
        append_log("unmodelled", drawn, f"listed exactly on {len(drawn) - len(wrong)}/{len(drawn)}", not wrong)
    assert not wrong, wrong


def _two_effects(seed: int) -> dict[str, bool]:
    """Seed ``seed`` of the freezing knee and the later loss: each criterion, True or False."""
    case = draw_case(seed, "temperature_dependent_stiffness", kind="girder", n_windows=WINDOWS,
                     form="bilinear", second_step=True)
    v, d = _run(case)
    gaps = _evidence_gaps(d)
    found = [m for m in d["missing_physics"] if m["name"] != "unmodelled_modes"]
    names = [m["name"] for m in found]
    out = {"both": "temperature_dependent_stiffness" in names and "stiffness_change_at_time" in names,
           "evidence": not gaps}
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
    """Up to three reduced cases (the first seeds of the full-size row): both effects named in at
    least one. At this size with the drifting misfit both were named on 18 of development seeds
    9300-9319 (d313ab1; 3 of 9300-9307 before the step's full prior, docs/explain.md "Tests and
    benchmarks"): at that rate three cases all fail with (2/20)^3 = 0.1 %. Every criterion together
    holds on too few cases for a 99 % check (11 of those 20 at this size; 12 of 15 at full size at dec662b, 11 at
    f75f73e, both named on all 15): the cases' other checks are printed, and asserted at full size. A further case runs only
    when the ones before do not name both (about 50 s each)."""
    rows = {}
    for seed in seeds("two_effects", TWO_CI):
        rows[seed] = _two_effects(seed)
        if rows[seed]["both"]:
            break
    print(f"two effects, reduced: {rows}")
    assert any(c["both"] for c in rows.values()), rows
    assert all(c["evidence"] for c in rows.values()), rows


@pytest.mark.skipif(not FULL, reason="full size only (SHM_FULL=1)")
def test_two_effects_over_seeds():
    """15 seeds; every criterion in at least 13 (the named cases' 90 % per check, 13.5 of 15, less
    the half case a finite count cannot meet)."""
    drawn = seeds("two_effects", TWO)
    with ProcessPoolExecutor(2) as pool:  # the named cases' test runs beside it: two cores in all
        rows = dict(zip(drawn, pool.map(_two_effects, drawn), strict=True))
    bad = {seed: [k for k, ok in c.items() if not ok] for seed, c in rows.items() if not all(c.values())}
    both = sum(c["both"] for c in rows.values())
    figures = f"both effects named {both}/{TWO}, every criterion {TWO - len(bad)}/{TWO}; failures {bad}"
    print(f"two effects: {figures}")
    append_log("two_effects", drawn, figures, TWO - len(bad) >= 13)
    assert TWO - len(bad) >= 13, bad


def append_log(row: str, drawn: list[int], figures: str, passed: bool) -> None:
    """One line per full-size run of a row at the end of docs/results/explain_dense_log.md, passed or
    failed: date, commit, core tree, the row's seeds (first seed + count: they are consecutive) and
    its figures (test_recorded_dense_seeds_follow_from_the_recorded_tree checks the seeds)."""
    import subprocess
    from datetime import UTC, datetime

    def git(*a: str) -> str:
        return subprocess.run(["git", "-C", str(LOG.parents[2]), *a], capture_output=True, text=True).stdout.strip()

    dirty = " (with uncommitted changes)" if git("status", "--porcelain", "--", "shm_ros", "test") else ""
    with LOG.open("a") as fh:
        fh.write(f"- {datetime.now(UTC):%Y-%m-%d %H:%M} UTC, commit {git('rev-parse', '--short', 'HEAD')}{dirty}, "
                 f"core tree `{core_tree()}`, row `{row}`, seeds `{drawn[0]}+{len(drawn)}`: {figures}: "
                 + ("**passes**" if passed else "**fails**") + "\n")


def test_recorded_dense_seeds_follow_from_the_recorded_tree():
    """Every full-size run in the log used the seeds its core tree gives (no seed chosen by hand),
    from the acceptance range (never a development seed)."""
    found = re.findall(r"core tree `([0-9a-f]{40})`, row `([a-z_:]+)`, seeds `(\d+)\+(\d+)`", LOG.read_text())
    for tree, row, first, n in found:
        assert seeds(row, int(n), tree) == list(range(int(first), int(first) + int(n))), (tree, row)
        assert int(first) >= DEV_SEEDS
