"""The full-size fault runs: 20 graph runs with injected faults per kind, their result in
``docs/results/fault_runs.json`` (with the commit and the date).

    nice -n 10 .venv/bin/python -m bench.fault_runs                  # every kind, 20 runs each
    nice -n 10 .venv/bin/python -m bench.fault_runs --kinds close --runs 5

Each kind is a test of ``test/test_graph_stops.py`` or ``test/test_graph_stops_analysis.py`` (real node
processes under ``shm-ros run``, real DDS, faults from ``SHM_FAULT``), run with ``SHM_FULL=1``:

- ``kill_points``: the recorder killed in a bag write, identify after publishing, track in its store's
  commit, at 20 kill-point sets drawn from a fixed seed; SIGTERM to the group during the replay, a
  rerun, Ctrl-C to the group (the test's own 20 parameters, one pytest run);
- ``analysis``: update, predict and explain killed after publishing, then a rerun of the bag into a
  fresh graph (one pytest run per run);
- ``close``: the recorder killed as it closes its bag at a Ctrl-C to the group (one pytest run per run).

What each run asserts is the test's (every window's outputs once, the exit code, no traceback,
nothing left running, ...). The file is written again after every run, so an interrupted campaign
keeps what ran (``finished`` false); each kind keeps its own latest campaign. Each pytest run gets
``ROS_DOMAIN_ID`` from ``--domain`` (default: this process's environment, else 183). Exit status 1
when a run failed.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path
from tempfile import TemporaryDirectory

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results" / "fault_runs.json"
KINDS = {
    "kill_points": "test/test_graph_stops.py::test_faults_sigterm_during_a_replay_and_ctrl_c_of_the_group_"
                   "lose_and_duplicate_nothing",
    "analysis": "test/test_graph_stops_analysis.py::test_update_predict_and_explain_killed_after_publishing_"
                "come_back_with_the_same_results",
    "close": "test/test_graph_stops.py::test_the_recorder_killed_as_it_closes_its_bag_at_a_ctrl_c_keeps_"
             "every_window_for_the_next_start",
}
#: kinds whose test is parametrized with its 20 runs at full size (one pytest run holds them all)
PARAMETRIZED = {"kill_points"}


def _commit() -> str:
    run = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT,
                           capture_output=True, text=True).stdout.strip()
    return run.stdout.strip() + ("+changes" if dirty else "")


def _excerpt(message: str) -> str:
    """A failure's message, its beginning (the assertion) and its end (the graph's last lines)."""
    return message if len(message) <= 1000 else f"{message[:300]} ... {message[-700:]}"


def _pytest(target: str, env: dict[str, str], timeout_s: float) -> list[dict]:
    """One pytest run of ``target``: per test case its id, outcome, seconds and (failed) the end of
    the message; the children's CPU time of the run in the last entry's ``cpu_s``."""
    with TemporaryDirectory(prefix="shm_fault_runs_") as tmp:
        xml = Path(tmp) / "junit.xml"
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        try:
            proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "0", "-p", "no:cacheprovider",
                                   f"--junitxml={xml}", target], cwd=ROOT, env=env, capture_output=True,
                                  text=True, timeout=timeout_s)
            tail = (proc.stdout + proc.stderr)[-1500:]
        except subprocess.TimeoutExpired as exc:
            tail = f"timed out after {timeout_s:g} s: {str(exc.stdout or '')[-1000:]}"
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        cases = []
        if xml.exists():
            for case in ET.parse(xml).getroot().iter("testcase"):
                failed = case.find("failure") if case.find("failure") is not None else case.find("error")
                skipped = case.find("skipped") is not None
                cases.append({"test": case.get("name", ""), "seconds": round(float(case.get("time", 0.0)), 1),
                              "outcome": "failed" if failed is not None else "skipped" if skipped else "passed",
                              **({"message": _excerpt(failed.get("message") or "")} if failed is not None else {})})
        if not cases:  # no report: the run itself failed (collection, timeout)
            cases.append({"test": target, "seconds": 0.0, "outcome": "failed", "message": tail[-400:]})
        cases[-1]["cpu_s"] = round(cpu, 1)
        return cases


def _summary(kind: str, cases: list[dict], wall: float) -> dict:
    return {"test": KINDS[kind], "runs": len(cases), "passed": sum(c["outcome"] == "passed" for c in cases),
            "failed": sum(c["outcome"] == "failed" for c in cases), "wall_s": round(wall, 1),
            "cpu_s": round(sum(c.get("cpu_s", 0.0) for c in cases), 1), "cases": cases}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--kinds", nargs="+", choices=sorted(KINDS), default=list(KINDS))
    p.add_argument("--runs", type=int, default=20, help="runs of each kind that is not parametrized")
    p.add_argument("--timeout", type=float, default=3600.0, help="seconds one pytest run may take")
    p.add_argument("--domain", default=os.environ.get("ROS_DOMAIN_ID", "183"))
    p.add_argument("--out", type=Path, default=RESULTS)
    a = p.parse_args(argv)
    env = {**os.environ, "SHM_FULL": "1", "ROS_DOMAIN_ID": str(a.domain), "SHM_TEST_DOMAIN_BASE": str(a.domain),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    command = "python -m bench.fault_runs " + " ".join(argv if argv is not None else sys.argv[1:])
    # each kind keeps its own latest campaign: a run of some kinds leaves the others' results
    result = json.loads(a.out.read_text()) if a.out.exists() else {}
    for kind in a.kinds:
        cases: list[dict] = []
        started = time.monotonic()
        head = {"command": command.strip(), "commit": _commit(),
                "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                "load_average_at_start": [round(v, 2) for v in os.getloadavg()]}
        for _ in range(1 if kind in PARAMETRIZED else a.runs):
            cases += _pytest(KINDS[kind], env, a.timeout)
            result[kind] = {**head, **_summary(kind, cases, time.monotonic() - started),
                            "finished": len(cases) >= a.runs or kind in PARAMETRIZED}
            a.out.parent.mkdir(parents=True, exist_ok=True)
            a.out.write_text(json.dumps(result, indent=1) + "\n")
            print(f"{kind}: {result[kind]['passed']} of {len(cases)} passed", flush=True)
    failed = sum(result[k]["failed"] for k in a.kinds)
    print(json.dumps({k: {f: result[k][f] for f in ("runs", "passed", "failed", "wall_s", "cpu_s")}
                      for k in a.kinds}, indent=1))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
