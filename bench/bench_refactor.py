"""CPU cost of ingest, replay reading and identify, to compare two versions of the code.

    python -m bench.bench_refactor                          # this checkout
    python -m bench.bench_refactor --before 4658c8d         # that commit, then this checkout
    python -m bench.bench_refactor --repo /path/a --repo /path/b --windows 2 --window-s 60

Each version is measured in its own process whose ``PYTHONPATH`` is that version's tree (a
``--before`` commit is exported with ``git archive`` into a temporary directory), one after the
other, on the same input: a per-sample ``sensor_msgs/Imu`` bag of the simulated ``building``
scenario, made once by this checkout's ``shm-ros simulate`` (fixed seed) and cached. Only entry
points that stay put across refactors are used: ``shm_ros.io.recording.ingest_bag`` (the function
behind ``shm-ros ingest``), ``shm_ros.io.structure.load_structure``, the replay module's bag
reader, and ``shm_ros.core.identify.identify_window``.

What is measured (CPU time of the measuring process, ``time.process_time``, BLAS on one thread;
median of ``--runs`` runs, after one untimed warm-up run):

* ingest, per channel sample: ``ingest_bag(bag, structure, window_s)`` (read, decode, check,
  snap to the grid, cut and check windows) over the whole bag;
* replay, per channel sample: the part of ``shm-ros replay`` that runs before DDS, i.e. opening
  the bag the way ``shm_ros.ros.replay`` does and iterating its recording topics' messages (CDR
  bytes, receive time, topic), which is all the replayer does per message besides ``publish``;
  publishing and the ingest node on the other side are not included (``bench_replay`` has them);
* identify, per window: ``identify_window`` with ``method="ssi-cov"`` (defaults otherwise, so
  with the jackknife uncertainty) on every window ``ingest_bag`` cut.

The windows and samples counted, and the modes found, are printed with the figures: two versions
that do the same work give the same counts. Writes ``bench/results/bench_refactor.json``. Not part
of ``.ci/run`` (nor of ``python -m bench`` without names).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results"
CACHE = Path(os.environ.get("SHM_BENCH_CACHE", Path(tempfile.gettempdir()) / "shm_bench_refactor"))
ONE_THREAD = {k: "1" for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}


# ---------------------------------------------------------------------------------------------
# input: a simulated bag, made once


def make_input(windows: int, window_s: float, seed: int = 0) -> Path:
    """``shm-ros simulate building`` with per-sample Imu into the cache (kept between runs)."""
    out = CACHE / f"building_imu_{windows}x{window_s:g}s_seed{seed}"
    if (out / "structure.yaml").exists() and (out / "bag").is_dir():
        return out
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".partial")
    cmd = [sys.executable, "-m", "shm_ros.cli", "simulate", "building", "--out", str(tmp),
           "--windows", str(windows), "--window-s", str(window_s), "--format", "imu",
           "--seed", str(seed), "--quiet"]
    subprocess.run(cmd, check=True, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT), **ONE_THREAD))
    tmp.rename(out)
    return out


# ---------------------------------------------------------------------------------------------
# measuring, inside a process whose PYTHONPATH is the version under test


def _replay_reader(bag: Path):
    """The bag reader ``shm_ros.ros.replay`` uses: ``_open_bag`` returns (topics, reader, ...)
    in every version; without it, the public reader of ``shm_ros.io.bags``."""
    try:
        from shm_ros.ros.replay import _open_bag

        opened = _open_bag(bag)
        return opened[0], opened[1]
    except ImportError:
        from shm_ros.io.bags import bag_topics, read_messages

        return bag_topics(bag), lambda wanted: read_messages(bag, topics=wanted)


def _replay_pass(bag: Path) -> int:
    from shm_ros.io.bags import topic_kind

    found, reader = _replay_reader(bag)
    wanted = [t for t, msgtype in found.items() if topic_kind(t, msgtype) is not None]
    n = 0
    for m in reader(wanted):
        n += len(m.data) > 0 and m.receive_ns > 0 and bool(m.topic)
    return n


# where ``ingest_bag`` lives, newest first; a version without the first has the next
INGEST_MODULES = ("shm_ros.io.recording", "shm_ros.io.sources.recording", "shm_ros.io.ingest")


def _ingest_bag():
    """``ingest_bag`` from the first of ``INGEST_MODULES`` that exists and has it; only a missing
    module is skipped (an import error inside an existing one is a bug and propagates)."""
    import importlib

    for name in INGEST_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name and name.startswith(exc.name):
                continue
            raise
        if hasattr(module, "ingest_bag"):
            return module.ingest_bag, name
    raise ImportError(f"ingest_bag not found in any of {INGEST_MODULES}")


def _median_cpu(fn, runs: int) -> tuple[float, list[float], Any]:
    out = fn()  # warm-up: imports, caches
    times = []
    for _ in range(runs):
        c0 = time.process_time()
        out = fn()
        times.append(time.process_time() - c0)
    return statistics.median(times), times, out


def measure(input_dir: Path, runs: int, window_s: float) -> dict:
    import shm_ros
    from shm_ros.core.identify import IdentifyConfig, identify_window
    from shm_ros.io.structure import load_structure

    ingest_bag, ingest_module = _ingest_bag()  # the function behind `shm-ros ingest`

    bag = input_dir / "bag"
    spec = load_structure(input_dir / "structure.yaml")
    ingest_s, ingest_runs, res = _median_cpu(lambda: ingest_bag(bag, spec, window_s=window_s), runs)
    samples = int(res.stats.samples_in)
    windows = list(res.windows)
    replay_s, replay_runs, messages = _median_cpu(lambda: _replay_pass(bag), runs)
    config = IdentifyConfig(method="ssi-cov")
    modes: list[int] = []

    def identify_all() -> list[int]:
        return [len(identify_window(w, config).modes) for w in windows]

    identify_s, identify_runs, modes = _median_cpu(identify_all, runs) if windows else (0.0, [], [])
    return {
        "shm_ros": str(Path(shm_ros.__file__).resolve().parents[1]),
        "ingest_bag_from": ingest_module,
        "channel_samples": samples,
        "samples_windowed": int(res.stats.samples_windowed),
        "windows": len(windows),
        "messages": messages,
        "modes_per_window": modes,
        "ingest_cpu_s": ingest_runs,
        "replay_cpu_s": replay_runs,
        "identify_cpu_s": identify_runs,
        "ingest_us_per_sample": 1e6 * ingest_s / max(samples, 1),
        "replay_us_per_sample": 1e6 * replay_s / max(samples, 1),
        "identify_s_per_window": identify_s / max(len(windows), 1),
    }


# ---------------------------------------------------------------------------------------------
# driving: one process per version


def export_commit(commit: str, into: Path) -> Path:
    """The tree of ``commit`` (of this checkout's repository) as plain files under ``into``."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", commit],
                             check=True, capture_output=True).stdout
    tar_path = into / "tree.tar"
    tar_path.write_bytes(archive)
    tree = into / "tree"
    with tarfile.open(tar_path) as tar:
        tar.extractall(tree, filter="data")
    return tree


def measure_tree(tree: Path, input_dir: Path, runs: int, window_s: float) -> dict:
    # run as a script (not ``-m bench...``) so that only ``tree`` provides ``shm_ros``
    env = dict(os.environ, PYTHONPATH=str(tree), **ONE_THREAD)
    cmd = [sys.executable, str(Path(__file__).resolve()), "--measure", str(input_dir),
           "--runs", str(runs), "--window-s", str(window_s)]
    run = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=tree)
    if run.returncode != 0:
        raise RuntimeError(f"measuring {tree} failed:\n{run.stderr[-3000:]}")
    result = json.loads(run.stdout.strip().splitlines()[-1])
    if Path(result["shm_ros"]) != tree.resolve():
        raise RuntimeError(f"measured {result['shm_ros']} instead of {tree}")
    return result


def _table(rows: dict[str, dict]) -> str:
    lines = ["| version | ingest µs/sample | replay read µs/sample | identify s/window | channel samples | "
             "windows | messages | modes found |", "|---" * 8 + "|"]
    for label, r in rows.items():
        lines.append(f"| {label} | {r['ingest_us_per_sample']:.3f} | {r['replay_us_per_sample']:.3f} | "
                     f"{r['identify_s_per_window']:.3f} | {r['channel_samples']:,} | {r['windows']} | "
                     f"{r['messages']:,} | {sum(r['modes_per_window'])} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--before", help="commit to measure first (exported with git archive)")
    ap.add_argument("--repo", type=Path, action="append", default=[],
                    help="another checkout to measure (repeatable); this checkout is measured last")
    ap.add_argument("--windows", type=int, default=6, help="simulated windows (default 6)")
    ap.add_argument("--window-s", type=float, default=600.0, help="window length, s (default 600)")
    ap.add_argument("--runs", type=int, default=5, help="timed runs per figure (median; default 5)")
    ap.add_argument("--measure", type=Path, help=argparse.SUPPRESS)  # worker mode: input dir
    args = ap.parse_args(argv)
    if args.measure is not None:
        print(json.dumps(measure(args.measure, args.runs, args.window_s)))
        return 0

    input_dir = make_input(args.windows, args.window_s)
    rows: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="bench_refactor_") as tmp:
        targets: list[tuple[str, Path]] = []
        if args.before:
            rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", args.before], check=True,
                                 capture_output=True, text=True).stdout.strip()
            targets.append((f"before ({rev})", export_commit(args.before, Path(tmp))))
        targets += [(str(p), p.resolve()) for p in args.repo]
        head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True).stdout.strip()
        targets.append((f"this checkout ({head or ROOT})", ROOT))
        for label, tree in targets:
            print(f"measuring {label} ...", file=sys.stderr, flush=True)
            rows[label] = measure_tree(tree, input_dir, args.runs, args.window_s)
    print(_table(rows))
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "bench_refactor.json").write_text(json.dumps({
        "input": str(input_dir), "windows": args.windows, "window_s": args.window_s, "runs": args.runs,
        "load_average": os.getloadavg(), "python": platform.python_version(), "versions": rows,
    }, indent=1))
    counts = {(r["channel_samples"], r["samples_windowed"], r["windows"], r["messages"]) for r in rows.values()}
    if len(counts) > 1:
        print("note: the versions did not do the same work (counts differ)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
