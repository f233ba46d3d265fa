"""explain's acceptance on the independent OpenSeesPy truths (docs/explain.md, Acceptance).

    nice .venv/bin/python -m bench.explain_acceptance [--size reduced|full] [--per-kind N] [--only ROWS]
        [--dev-seeds | --seeds S ...] [--jobs 2] [--no-log]

Every row of the acceptance runs: the sparse earthquake kinds (OpenSeesPy event campaigns through
``shm-ros explain --bag``: per-event modal estimates and the time-domain path), the nulls (dense and
sparse), the second row (transient softening, lagged temperature) and the effects outside the
vocabulary; the acceptable verdicts are the table below (:data:`ROWS`), the figures are judged by
:data:`CRITERIA`. Seeds: without ``--dev-seeds``/``--seeds`` the acceptance seeds that the git tree of
``shm_ros/core`` at HEAD gives (it holds the shipped threshold files,
``shm_ros/core/explain/threshold*.json``; :func:`acceptance_seeds.explain_seeds`), from a range
disjoint from the development seeds (0 .. :data:`acceptance_seeds.DEV_SEEDS` - 1). Every run is
appended to the log at the end of docs/explain.md (commit, tree, seeds, figures, pass/fail per
criterion), failed ones too; a run on development seeds or at reduced size says so in its log entry.
At most 2 worker processes, each at ``nice`` 10.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))

from acceptance_seeds import DEV_SEEDS, core_tree, explain_seeds  # noqa: E402

DOC = ROOT / "docs" / "explain.md"
LOG_HEADING = "## Acceptance log"

# -- the acceptable verdicts (the table, as data) -----------------------------------------------


@dataclass(frozen=True)
class Row:
    """One acceptance row: its truth kinds and the rule that judges a verdict (``judge``'s key)."""

    name: str
    kinds: tuple[str, ...]
    rule: str
    expected: tuple[str, ...] = ()  # sparse rows: the right names
    full: int = 20  # campaigns at full size (the row's share of the counts)


ROWS: tuple[Row, ...] = (
    Row("stiffness_loss", ("event_stiffness_loss",), "stiffness_loss", ("stiffness_change_at_time",)),
    Row("hysteretic", ("event_hysteretic",), "right_name", ("amplitude_dependent_stiffness",)),
    Row("amplitude_damping", ("event_amplitude_damping",), "right_name", ("amplitude_dependent_damping",)),
    Row("soil", ("event_soil",), "right_name", ("support_flexibility",)),
    Row("damper_loss", ("event_damper_loss",), "damper_loss", ("damper_stiffness", "stiffness_change_at_time")),
    # nulls: no name except unmodelled_modes (unexplained_structure allowed, counted)
    Row("nulls", ("dense_ar1_null", "dense_random_walk_null", "dense_clean", "event_clean"), "null", full=100),
    # second row: amplitude / temperature names or none; never a step
    Row("transient_or_lagged", ("event_transient_softening", "dense_lagged_temperature"), "no_step", full=40),
    # outside the vocabulary (the table's last four rows)
    Row("humidity", ("dense_humidity",), "humidity", full=13),
    Row("stick_slip", ("dense_stick_slip",), "stick_slip", full=13),
    Row("settlement", ("dense_settlement",), "settlement", full=12),
    Row("breathing_crack", ("event_breathing_crack",), "right_name", ("amplitude_dependent_stiffness",), full=12),
)
SPARSE_ROWS = ("stiffness_loss", "hysteretic", "amplitude_damping", "soil", "damper_loss")
OUTSIDE_ROWS = ("humidity", "stick_slip", "settlement", "breathing_crack")

# name -> (what is counted, bound, "min" or "max"); rates over the row's campaigns
CRITERIA: dict[str, tuple[str, float, str]] = {
    "stiffness_loss": ("confident right name, time and stories right", 0.90, "min"),
    "hysteretic": ("confident right name", 0.90, "min"),
    "amplitude_damping": ("confident right name", 0.80, "min"),
    "soil": ("confident right name", 0.80, "min"),
    "damper_loss": ("confident right name (a step at the damper's stories)", 0.80, "min"),
    "held_out_fall": ("sparse rows: median held-out misfit fall", 0.30, "min"),
    "form_fits_false": ("sparse rows: form_fits false", 0.10, "max"),
    "nulls_clean": ("nulls: no name except unmodelled_modes", 0.95, "min"),
    "nulls_step": ("nulls: stiffness_change_at_time named", 0.01, "max"),
    "nulls_unexplained": ("nulls: unexplained_structure", 0.20, "max"),
    "second_row_step": ("transient softening, lagged temperature: a step named", 0.02, "max"),
    "outside": ("outside the vocabulary: an acceptable verdict", 0.90, "min"),
}


def _names(v: dict) -> list[dict]:
    return [m for m in v.get("missing_physics", []) if m["name"] != "unmodelled_modes"]


def _stories(where: str | None) -> set[int]:
    """0-based stories of a ``where`` naming story groups (``EI:2`` -> {1}); empty for a whole-structure group."""
    out: set[int] = set()
    for part in str(where or "").replace("+", ",").split(","):
        part = part.strip()
        if part.startswith("EI:") and part[3:].isdigit():
            out.add(int(part[3:]) - 1)
    return out


def _where_right(where: str | None, truth: dict) -> bool:
    """``where`` names a damaged story (a story whose damper was lost), or the whole structure when
    every story was."""
    damaged = set(truth["effect"]["magnitudes"]["stories"])
    named = _stories(where)
    if not named and str(where or "").strip() == "EI":
        return damaged == set(range(int(truth.get("building", {}).get("stories", -1))))
    return bool(named & damaged)


def _time_right(entry: dict, truth: dict) -> bool:
    """The effect's time between the event before the change and the first event after it."""
    k = truth.get("effect", {}).get("change_event")
    t = entry.get("time")
    if k is None or t is None or not (0 < int(k) < len(truth["events"])):
        return False
    ts = [datetime.fromisoformat(str(e["time"]).replace("Z", "+00:00")).timestamp() for e in truth["events"]]
    x = datetime.fromisoformat(str(t).replace("Z", "+00:00")).timestamp()
    return ts[int(k) - 1] < x <= ts[int(k)] + 1.0


def _confident(m: dict) -> bool:
    return m.get("form_fits") is not False and not m.get("downgraded_by")


def held_out_fall(v: dict) -> float | None:
    """Relative fall of the held-out misfit after the accepted effects: the larger of the modal path's
    (frequency RMSE) and the time path's (NRMS)."""
    falls = []
    ho = v.get("fit", {}).get("held_out", {})
    td = v.get("fit", {}).get("fit_ratio", {}).get("time_domain_scores", {})
    for before, after in ((ho.get("before", {}), ho.get("after", {})),
                          (td.get("held_out_before", {}), td.get("held_out_after", {}))):
        for key in ("frequency_rmse_pct", "nrms_pct"):
            b, a = before.get(key), after.get(key)
            if b and a is not None and b > 0:
                falls.append(1.0 - a / b)
    return max(falls) if falls else None


def judge(row: Row, v: dict, truth: dict) -> dict:
    """One campaign's verdict against its row: ``ok`` and the counts the criteria use."""
    named = _names(v)
    first = named[0] if named else None
    names = {m["name"] for m in named}
    out: dict = {"names": [m["name"] for m in named], "unexplained": v.get("unexplained_structure") is not None,
                 "step": "stiffness_change_at_time" in names, "fit_ratio": v.get("fit_ratio"),
                 "form_fits_false": bool(first is not None and first.get("form_fits") is False)}
    if row.rule in ("right_name", "stiffness_loss", "damper_loss"):
        ok = first is not None and first["name"] in row.expected[:1] and _confident(first)
        if row.rule == "stiffness_loss":
            ok = ok and _time_right(first, truth) and _where_right(first.get("where"), truth)
        if row.rule == "damper_loss" and first is not None and _confident(first):
            ok = first["name"] == "damper_stiffness" or (
                first["name"] == "stiffness_change_at_time" and _where_right(first.get("where"), truth))
        out["held_out_fall"] = held_out_fall(v)
    elif row.rule == "null":
        ok = not named
    elif row.rule == "no_step":
        ok = not out["step"] and names <= {"amplitude_dependent_stiffness", "temperature_dependent_stiffness"}
    elif row.rule == "humidity":
        ok = (out["unexplained"] and not named) or (bool(named) and all(m.get("form_fits") is False for m in named))
    elif row.rule == "stick_slip":
        ok = (out["unexplained"] and not named) or bool(
            first and first["name"] == "amplitude_dependent_stiffness" and first.get("form_fits") is False)
    elif row.rule == "settlement":
        ok = first is not None and (first["name"] == "support_flexibility" or (
            first["name"] == "stiffness_change_at_time" and _settled_in_time(first, truth)))
    else:
        raise ValueError(f"unknown rule {row.rule}")
    out["ok"] = bool(ok)
    return out


def _settled_in_time(entry: dict, truth: dict) -> bool:
    """A dense step's first window after the change within 3 windows of the truth's change window."""
    w = entry.get("change_window")
    return w is not None and truth.get("change_window") is not None and abs(int(w) - int(truth["change_window"])) <= 3


# -- one campaign ---------------------------------------------------------------------------------------


def run_one(task: tuple[str, str, int, str]) -> dict:
    """Generate one campaign, explain it (``--bag`` for events, ``--modes`` for tables), judge it."""
    row_name, kind, seed, size = task
    from truths import make_campaign

    from shm_ros.cli import main as shm_ros

    row = next(r for r in ROWS if r.name == row_name)
    work = Path(tempfile.mkdtemp(prefix=f"acc-{kind}-{seed}-"))
    t0 = time.process_time()
    try:
        c = make_campaign(kind, seed, size, work / "campaign")
        t_gen = time.process_time() - t0
        out = work / "explain"
        src = ["--bag", str(c.data)] if c.is_event else ["--modes", str(c.data)]
        import contextlib
        import io

        err = io.StringIO()
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
            code = shm_ros(["explain", "--structure", str(c.structure), *src, "--out", str(out), "--no-report"])
        if code not in (0, 3) or not (out / "verdict.json").exists():  # 3: a verdict that says no window
            return {"row": row_name, "kind": kind, "seed": seed, "ok": False, "error": f"exit {code}: "
                    f"{err.getvalue().strip().splitlines()[-1:]}", "cpu_s": time.process_time() - t0}
        v = json.loads((out / "verdict.json").read_text())
        truth = json.loads(c.truth.read_text())
        res = judge(row, v, truth)
        return {"row": row_name, "kind": kind, "seed": seed, **res, "status": v.get("status"),
                "generate_cpu_s": round(t_gen, 1), "cpu_s": round(time.process_time() - t0, 1)}
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _nice() -> None:
    """Niceness 10 for a worker (not more when started under ``nice`` already: 19 starves on a shared machine)."""
    os.nice(max(10 - os.nice(0), 0))
    os.environ.setdefault("OMP_NUM_THREADS", "1")


def tasks_for(rows: list[Row], size: str, per_kind: int | None, seeds: list[int] | None,
              dev: bool, tree: str) -> tuple[list[tuple[str, str, int, str]], dict[str, list[int]]]:
    """(row, kind, seed, size) of every campaign and each row's seeds: a row's count (``per_kind``
    campaigns per kind, default its full-size share) spread over its kinds, the i-th seed of the row
    for the i-th campaign of each kind (seeds from the tree, or given / development)."""
    tasks, used = [], {}
    for row in rows:
        K = len(row.kinds)
        n = per_kind * K if per_kind else row.full
        m = -(-n // K)
        if seeds is not None:
            pool = [seeds[i % len(seeds)] for i in range(m)]
        elif dev:
            pool = list(range(m))
        else:
            pool = explain_seeds(m, tree, row.name)
        used[row.name] = pool
        tasks += [(row.name, row.kinds[j % K], pool[j // K], size) for j in range(n)]
    return tasks, used


def figures(results: list[dict]) -> dict[str, dict]:
    """Each criterion's figure, count and pass/fail."""
    by_row: dict[str, list[dict]] = {}
    for r in results:
        by_row.setdefault(r["row"], []).append(r)

    def rate(rs: list[dict], key: str) -> tuple[float, int]:
        return (sum(bool(r.get(key)) for r in rs) / len(rs), len(rs)) if rs else (math.nan, 0)

    values: dict[str, tuple[float, int]] = {}
    for name in SPARSE_ROWS:
        if name in by_row:
            values[name] = rate(by_row[name], "ok")
    sparse = [r for n in SPARSE_ROWS for r in by_row.get(n, [])]
    falls = sorted(r["held_out_fall"] for r in sparse if r.get("held_out_fall") is not None)
    if sparse:
        values["held_out_fall"] = (falls[len(falls) // 2] if falls else math.nan, len(sparse))
        values["form_fits_false"] = rate(sparse, "form_fits_false")
    if "nulls" in by_row:
        values["nulls_clean"] = rate(by_row["nulls"], "ok")
        values["nulls_step"] = rate(by_row["nulls"], "step")
        values["nulls_unexplained"] = rate(by_row["nulls"], "unexplained")
    if "transient_or_lagged" in by_row:
        values["second_row_step"] = rate(by_row["transient_or_lagged"], "step")
    outside = [r for n in OUTSIDE_ROWS for r in by_row.get(n, [])]
    if outside:
        values["outside"] = rate(outside, "ok")
    out = {}
    for key, (value, n) in values.items():
        what, bound, sense = CRITERIA[key]
        ok = math.isfinite(value) and (value >= bound if sense == "min" else value <= bound)
        out[key] = {"what": what, "value": value, "n": n, "bound": bound, "sense": sense, "pass": bool(ok)}
    return out


def log_entry(meta: dict, figs: dict, results: list[dict]) -> str:
    """The docs' log entry of one run (markdown; the seeds line is what the seeds test re-derives)."""
    lines = [f"### {meta['date']} — {meta['kind']}", "",
             f"- commit `{meta['commit']}`, core tree `{meta['tree']}`"
             f"{' (core changed since: dirty)' if meta['dirty'] else ''}",
             f"- command: `{meta['command']}`",
             f"- size: {meta['size']}; campaigns: {len(results)}; CPU {meta['cpu_s']:.0f} s, "
             f"wall {meta['wall_s']:.0f} s",
             f"- seeds: {meta['seed_kind']}: " + "; ".join(f"{row} {','.join(map(str, s))}"
                                                          for row, s in meta["seeds"].items()),
             "", "| criterion | what | figure | campaigns | bound | pass |", "|---|---|---|---|---|---|"]
    for key, f in figs.items():
        sign = ">=" if f["sense"] == "min" else "<="
        lines.append(f"| {key} | {f['what']} | {f['value']:.2f} | {f['n']} | {sign} {f['bound']:g} | "
                     f"{'yes' if f['pass'] else 'NO'} |")
    per_row: dict[str, list[str]] = {}
    for r in results:
        per_row.setdefault(r["row"], []).append(
            f"{r['kind']}/{r['seed']}:{'ok' if r.get('ok') else 'x'}"
            f"[{','.join(r.get('names', [])) or r.get('error', 'none')}]")
    lines += ["", "<details><summary>per campaign</summary>", ""]
    lines += [f"- {row}: {' '.join(items)}" for row, items in per_row.items()]
    lines += ["", "</details>", ""]
    return "\n".join(lines)


def append_log(entry: str, doc: Path = DOC) -> None:
    text = doc.read_text()
    if LOG_HEADING not in text:
        text = text.rstrip("\n") + f"\n\n{LOG_HEADING}\n\nEvery run of `bench/explain_acceptance.py`, failed ones " \
            "too (newest last). `test/test_explain_acceptance_seeds.py` checks that the seeds of every " \
            "entry on acceptance seeds are the ones its core tree gives.\n"
    doc.write_text(text.rstrip("\n") + "\n\n" + entry)


def _git(*a: str) -> str:
    return subprocess.run(["git", "-C", str(ROOT), *a], capture_output=True, text=True, check=False).stdout.strip()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.explain_acceptance", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", choices=("reduced", "full"), default="full")
    ap.add_argument("--per-kind", type=int, default=None, help="campaigns per kind (default: each row's full count)")
    ap.add_argument("--only", nargs="+", choices=[r.name for r in ROWS], help="rows to run (default: all)")
    src = ap.add_mutually_exclusive_group()
    src.add_argument("--dev-seeds", action="store_true", help=f"development seeds 0.. (< {DEV_SEEDS})")
    src.add_argument("--seeds", type=int, nargs="+", help="these development seeds")
    ap.add_argument("--jobs", type=int, default=2, choices=(1, 2))
    ap.add_argument("--no-log", action="store_true", help="do not append to docs/explain.md")
    args = ap.parse_args(argv)
    if args.seeds and any(not 0 <= s < DEV_SEEDS for s in args.seeds):
        ap.error(f"--seeds are development seeds, 0 .. {DEV_SEEDS - 1}")
    rows = [r for r in ROWS if not args.only or r.name in args.only]
    tree, commit = core_tree(), _git("rev-parse", "--short=12", "HEAD")  # the code the run starts with
    dirty = bool(_git("status", "--porcelain", "--", "shm_ros/core"))
    dev = bool(args.dev_seeds or args.seeds)
    tasks, seeds = tasks_for(rows, args.size, args.per_kind, args.seeds, dev, tree)
    t0, c0 = time.time(), time.process_time()
    results = []
    with mp.get_context("spawn").Pool(args.jobs, initializer=_nice) as pool:
        for r in pool.imap_unordered(run_one, tasks):
            results.append(r)
            print(f"[{len(results)}/{len(tasks)}] {r['row']:20s} {r['kind']:26s} seed {r['seed']:>8}: "
                  f"{'ok' if r.get('ok') else 'x '} {r.get('names', r.get('error'))} ({r.get('cpu_s')} s CPU)",
                  flush=True)
    cpu = time.process_time() - c0 + sum(r.get("cpu_s", 0.0) for r in results)
    figs = figures(results)
    meta = {"date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "kind": ("development" if dev else "acceptance") + (" (reduced size)" if args.size == "reduced" else ""),
            "commit": commit, "tree": tree, "dirty": dirty,
            "command": "nice .venv/bin/python -m bench.explain_acceptance " + " ".join(argv or sys.argv[1:]),
            "size": args.size, "cpu_s": cpu, "wall_s": time.time() - t0,
            "seed_kind": "development" if dev else "acceptance (explain_seeds of the core tree)", "seeds": seeds}
    entry = log_entry(meta, figs, results)
    print(entry)
    if not args.no_log:
        append_log(entry)
        print(f"appended to {DOC}")
    return 0 if all(f["pass"] for f in figs.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
