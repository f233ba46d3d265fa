"""``shm-ros batch`` throughput with 1 and 2 Dask workers on the same archive.

    python -m bench.bench_batch                 # 50 bags x 4 girder windows of 60 s = 200 windows
    python -m bench.bench_batch --bags 10       # a slice
    python -m bench.bench_batch --rounds 2      # 1, 2, 2, 1 workers in turn; medians per count

The archive (girder scenario, one structure file, 100 Hz ``AccelBlock``) is simulated once (not
timed); then ``run_batch`` on a local Dask cluster of 1 and of 2 single-threaded worker processes
(cluster start included, tracking only: no update), in turn (1, 2, 2, 1, ... workers, so that a
load that changes during the runs weighs on both counts alike; the median wall time per count).
Throughput = windows / wall second. Target:
2 workers >= 1.7 x 1 worker on >= 200 windows. The outputs of both runs must be equal (apart from
provenance). Writes ``bench/results/bench_batch.json``; on a machine whose other load leaves less
than two free cores the ratio says more about that load than about the batch (the load average is
recorded).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

RESULTS = Path(__file__).resolve().parent / "results"
TARGET = 1.7


def make_archive(root: Path, n_bags: int, windows: int) -> None:
    import yaml

    from shm_ros.core.simulate import named_scenario, simulate_campaign
    from shm_ros.io.campaign import write_campaign

    for k in range(n_bags):
        sc = named_scenario("girder")
        sc.n_windows, sc.window_s, sc.seed = windows, 60.0, 1000 + k
        sc.start = f"2024-01-01T{k // 6:02d}:{10 * (k % 6):02d}:00Z"
        write_campaign(simulate_campaign(sc), root / f"bag_{k:03d}")
    (root / "structure.yaml").write_text((root / "bag_000" / "structure.yaml").read_text())
    spec = yaml.safe_load((root / "structure.yaml").read_text())
    spec.pop("parameters", None)
    (root / "structure.yaml").write_text(yaml.safe_dump(spec))
    for k in range(n_bags):
        (root / f"bag_{k:03d}" / "structure.yaml").unlink()


def timed_run(root: Path, out: Path, workers: int) -> tuple[float, dict]:
    from shm_ros.batch.archive import archive
    from shm_ros.batch.engines import DaskEngine
    from shm_ros.batch.jobs import BatchSettings
    from shm_ros.batch.run import run_batch

    bags = archive([root])
    t0 = time.perf_counter()
    engine = DaskEngine(workers=workers)
    try:
        summary = run_batch(bags, BatchSettings(window_s=60.0, run_update=False), engine, out, log=lambda s: None)
    finally:
        engine.close()
    return time.perf_counter() - t0, summary


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bags", type=int, default=50)
    ap.add_argument("--windows-per-bag", type=int, default=4)
    ap.add_argument("--rounds", type=int, default=1, help="pairs of runs, in the order 1, 2, 2, 1, ... workers")
    args = ap.parse_args(argv)
    import statistics
    import subprocess

    order = [w for r in range(args.rounds) for w in ((1, 2) if r % 2 == 0 else (2, 1))]
    runs: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "archive"
        make_archive(root, args.bags, args.windows_per_bag)
        for k, workers in enumerate(order):
            load = os.getloadavg()[0]
            wall, summary = timed_run(root, Path(tmp) / f"out{k}_{workers}", workers)
            n = sum(b["identified"] for b in summary["bags"])
            runs.append({"workers": workers, "wall_s": wall, "windows": n, "load_average_1min_at_start": load})
            print(f"{workers} worker(s): {n} windows in {wall:.1f} s (load {load:.1f})", flush=True)
        out1, out2 = Path(tmp) / f"out{order.index(1)}_1", Path(tmp) / f"out{order.index(2)}_2"
        same = all((out1 / p.relative_to(out2)).is_file() for p in out2.rglob("*") if p.is_file())
    walls = {w: statistics.median(r["wall_s"] for r in runs if r["workers"] == w) for w in (1, 2)}
    ratio = walls[1] / walls[2]
    commit = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], capture_output=True, text=True,
                            cwd=Path(__file__).resolve().parent).stdout.strip()
    result = {"bags": args.bags, "windows": n, "wall_s": walls, "throughput_ratio": ratio, "target": TARGET,
              "same_files": same, "met": bool(n >= 200 and ratio >= TARGET), "load_average": list(os.getloadavg()),
              "runs": runs, "commit": commit, "date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime())}
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "bench_batch.json").write_text(json.dumps(result, indent=2))
    print(json.dumps(result, indent=2))
    return 0 if result["met"] else 1


if __name__ == "__main__":
    sys.exit(main())
