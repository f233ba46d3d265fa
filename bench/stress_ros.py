"""Stress run of the ROS and graph tests: the same tests N times in a row on a busy machine.

    python -m bench.stress_ros                      # 10 runs, 2 CPU-bound processes beside them
    python -m bench.stress_ros --runs 2 --files test/test_dds_smoke.py      # a short trial

The tests that start DDS participants and node processes (``test_dds_smoke``, ``test_interfaces``,
``test_*_node.py``, ``test_graph_*.py``, ``test_supervisor``, ``test_example``, the two-host, params-file,
sim-time, config-agreement and update-worker tests) wait on events, not
on the clock; this checks that they also pass when the cores are taken by other work: two Python
busy loops (``--burners``) run for the whole stress run, and each run is a fresh ``pytest``
process (so a fresh ROS domain id from ``test/conftest.py``). Prints the pass count of every run
and ``N/RUNS passed`` (a run passes when none of its tests failed or errored); writes
``bench/results/stress_ros.json`` (and the output of each failed run, ``stress_ros_run_K.log``);
exit status 1 unless every run passed. Not part of ``.ci/run``.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results"
PATTERNS = ("test_dds_smoke.py", "test_interfaces.py", "test_*_node.py", "test_node_*.py", "test_graph_*.py",
            "test_supervisor.py", "test_example.py", "test_two_hosts.py", "test_params_file.py",
            "test_sim_time.py", "test_config_agreement.py", "test_update_node_worker.py")
BUSY_LOOP = "while True: pass"


@dataclass
class RunResult:
    run: int
    tests: int = 0
    passed: int = 0
    failed: int = 0
    errors: int = 0
    skipped: int = 0
    exit_code: int = 0
    wall_s: float = 0.0
    not_passed: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.failed == 0 and self.errors == 0 and self.tests > 0 and self.exit_code == 0


def default_files(repo: Path) -> list[str]:
    """The ROS and graph test files present in ``repo`` (names may move between versions)."""
    found = {p for pattern in PATTERNS for p in (repo / "test").glob(pattern)}
    return [str(p.relative_to(repo)) for p in sorted(found)]


def _counts(junit: Path, result: RunResult) -> None:
    if not junit.exists():
        return
    root = ET.parse(junit).getroot()
    for suite in root.iter("testsuite"):
        result.tests += int(suite.get("tests", 0))
        result.failed += int(suite.get("failures", 0))
        result.errors += int(suite.get("errors", 0))
        result.skipped += int(suite.get("skipped", 0))
    for case in root.iter("testcase"):
        if case.find("failure") is not None or case.find("error") is not None:
            result.not_passed.append(f"{case.get('classname', '')}::{case.get('name', '')}")
    result.passed = result.tests - result.failed - result.errors - result.skipped


def run_once(k: int, repo: Path, files: list[str], extra: list[str], timeout_s: float,
             workdir: Path) -> RunResult:
    """One ``pytest`` process over ``files``; its whole process group is ended on a timeout."""
    junit = workdir / f"run_{k}.xml"
    env = dict(os.environ, PYTHONPATH=str(repo), OPENBLAS_NUM_THREADS="1")
    env.pop("ROS_DOMAIN_ID", None)  # each run picks its own (test/conftest.py)
    env.pop("SHM_FULL", None)
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", f"--junitxml={junit}",
           *extra, *files]
    result = RunResult(k)
    log = workdir / f"run_{k}.log"
    t0 = time.monotonic()
    with open(log, "w") as out:
        proc = subprocess.Popen(cmd, cwd=repo, env=env, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)
        try:
            result.exit_code = proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)  # pytest and the node processes it started
            proc.wait()
            result.exit_code = -9
            result.not_passed.append(f"(timed out after {timeout_s:g} s; log {log})")
    result.wall_s = round(time.monotonic() - t0, 1)
    _counts(junit, result)
    return result


def start_burners(n: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, "-c", BUSY_LOOP]) for _ in range(n)]


def stop_burners(burners: list[subprocess.Popen]) -> None:
    for proc in burners:
        proc.kill()
        proc.wait()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--burners", type=int, default=2, help="CPU-bound processes beside the tests")
    ap.add_argument("--files", nargs="+", help="test files (default: the ROS and graph tests)")
    ap.add_argument("--repo", type=Path, default=ROOT, help="checkout whose tests and code are run")
    ap.add_argument("--timeout", type=float, default=1800.0, help="per run, then it counts as failed")
    ap.add_argument("--pytest-args", default="", help="extra pytest arguments, e.g. \"-k smoke\"")
    args = ap.parse_args(argv)
    repo = args.repo.resolve()
    files = args.files or default_files(repo)
    if not files:
        print(f"no test files found in {repo / 'test'}", file=sys.stderr)
        return 2
    print(f"stress: {args.runs} runs of {len(files)} files with {args.burners} busy loops beside: "
          + " ".join(files), flush=True)
    runs: list[RunResult] = []
    burners = start_burners(args.burners)
    try:
        with tempfile.TemporaryDirectory(prefix="stress_ros_") as tmp:
            for k in range(1, args.runs + 1):
                r = run_once(k, repo, files, args.pytest_args.split(), args.timeout, Path(tmp))
                runs.append(r)
                if not r.ok:  # keep the output of a failed run
                    RESULTS.mkdir(parents=True, exist_ok=True)
                    kept = RESULTS / f"stress_ros_run_{k}.log"
                    kept.write_text((Path(tmp) / f"run_{k}.log").read_text())
                    r.not_passed.append(f"(output: {kept})")
                tail = f"; not passed: {', '.join(r.not_passed)}" if r.not_passed else ""
                print(f"run {k}/{args.runs}: {r.passed}/{r.tests} tests passed ({r.skipped} skipped) "
                      f"in {r.wall_s:.0f} s, {'ok' if r.ok else 'FAILED'}{tail}", flush=True)
    finally:
        stop_burners(burners)
    n_ok = sum(r.ok for r in runs)
    print(f"{n_ok}/{len(runs)} passed")
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "stress_ros.json").write_text(json.dumps({
        "repo": str(repo), "files": files, "burners": args.burners, "runs_passed": n_ok,
        "runs": [{**asdict(r), "ok": r.ok} for r in runs],
        "load_average": os.getloadavg(),
    }, indent=1))
    return 0 if n_ok == len(runs) else 1


if __name__ == "__main__":
    sys.exit(main())
