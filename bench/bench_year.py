"""A year of 10-minute windows: CPU per window of ingest + identify + track, and flat memory.

    python -m bench.bench_year                      # 1,000 girder windows + 10,000 synthetic estimates
    python -m bench.bench_year --windows 20 --estimates 2000    # a slice (figures per window)

Part 1: the graph bench's girder (``bench_graph.scenario``: twelve deck sensors, 100 Hz) with
10-minute windows is simulated and written as ``AccelBlock`` (not timed), then timed in CPU seconds
of this process, one BLAS thread: ``ingest_bag`` of the whole bag, ``identify_window`` of every
window with the defaults (the jackknife included) and the band of the structure's nominal model
(as ``shm-ros identify`` takes it), and the tracker's ``add``. Target: <= 0.13 s per window on
average (a year, 52,560 windows, on 2 cores in <= 57 minutes).

Part 2: the tracker and its SQLite history store fed synthetic modal estimates (five modes with
scatter and a temperature); the resident memory of the process and the Python heap traced by
tracemalloc after 1,000 and after ``--estimates`` windows. Target: within 50 MB.
Writes ``bench/results/bench_year.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
TARGET_CPU_S = 0.13
TARGET_MB = 50.0


def _rss_mb() -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def per_window_cpu(n_windows: int, work: Path, seed: int = 1) -> dict:
    from bench.bench_graph import scenario
    from shm_ros.core.band import band_frequencies
    from shm_ros.core.identify import IdentifyConfig, identify_window
    from shm_ros.core.simulate import simulate_campaign
    from shm_ros.core.tracking import TrackingConfig
    from shm_ros.core.tracking.online import Tracker
    from shm_ros.io.campaign import write_campaign
    from shm_ros.io.recording import ingest_bag
    from shm_ros.io.structure import load_structure

    files = write_campaign(simulate_campaign(scenario(n_windows, 600.0, 600.0, seed)), work / "campaign")
    spec = load_structure(files.structure)
    cfg = IdentifyConfig()
    cfg.nominal_frequencies_hz, _ = band_frequencies(spec, cfg.band, cfg.band_modes)
    tracker = Tracker(TrackingConfig(reference_windows=min(24, max(3, n_windows // 2))),
                      training_windows=max(3, min(144, n_windows // 2)))
    c0 = time.process_time()
    res = ingest_bag(files.bag, spec, window_s=600.0)
    c_ingest = time.process_time() - c0
    c_identify = c_track = 0.0
    modes = []
    for w in res.windows:
        c0 = time.process_time()
        est = identify_window(w, cfg)
        c1 = time.process_time()
        tracker.add(est)
        c_track += time.process_time() - c1
        c_identify += c1 - c0
        modes.append(len(est.modes))
    n = len(res.windows)
    total = c_ingest + c_identify + c_track
    return {"windows": n, "ingest_cpu_s": c_ingest / n, "identify_cpu_s": c_identify / n,
            "track_cpu_s": c_track / n, "total_cpu_s": total / n, "mean_modes": float(np.mean(modes)),
            "year_on_2_cores_min": total / n * 52560 / 2 / 60, "target_cpu_s": TARGET_CPU_S,
            "met": bool(n >= 1000 and total / n <= TARGET_CPU_S)}


def _estimate(k: int, rng: np.random.Generator):
    from shm_ros.core.types import ModalEstimate, Mode

    temp = 10 + 12 * np.sin(2 * np.pi * k / 52560) + rng.normal(0, 1)
    base = np.array([1.9, 3.4, 5.6, 7.9, 11.2]) * (1 - 0.002 * (temp - 10))
    shapes = np.sin(np.outer(np.arange(1, 6), np.linspace(0.3, 3.0, 12)))
    modes = [Mode(float(f * (1 + rng.normal(0, 0.003))), float(0.01 + abs(rng.normal(0, 0.002))),
                  shapes[i] + rng.normal(0, 0.02, 12), 0.99, n_poles=40)
             for i, f in enumerate(base) if rng.random() > 0.05]
    start = 1_700_000_000_000_000_000 + k * 600_000_000_000
    return ModalEstimate(f"w{k:06d}", start, start + 600_000_000_000, [f"s{i + 1}" for i in range(12)], modes,
                         temperature_c=float(temp))


def memory(n_estimates: int, work: Path) -> dict:
    from shm_ros.core.tracking import TrackingConfig
    from shm_ros.core.tracking.online import Tracker
    from shm_ros.io.store import TrackStore

    rng = np.random.default_rng(5)
    tracker = Tracker(TrackingConfig(reference_windows=24), training_windows=144)
    store = TrackStore(work / "track.sqlite")
    tracemalloc.start()
    marks: dict[int, dict] = {}
    for k in range(n_estimates):
        est = _estimate(k, rng)
        store.record(est, tracker.add(est), tracker)
        if k + 1 in (1000, n_estimates):
            marks[k + 1] = {"rss_mb": _rss_mb(), "traced_mb": tracemalloc.get_traced_memory()[0] / 2 ** 20,
                            "store_file_mb": (work / "track.sqlite").stat().st_size / 2 ** 20}
            print(f"after {k + 1} windows: {marks[k + 1]}", flush=True)
    tracemalloc.stop()
    store.close()
    first, last = marks[1000], marks[n_estimates]
    growth = max(last["rss_mb"] - first["rss_mb"], last["traced_mb"] - first["traced_mb"])
    return {"estimates": n_estimates, "after": marks, "growth_mb": growth, "target_mb": TARGET_MB,
            "met": bool(n_estimates >= 10000 and growth <= TARGET_MB)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--windows", type=int, default=1000, help="girder windows of 10 minutes (part 1)")
    ap.add_argument("--estimates", type=int, default=10000, help="synthetic estimates (part 2, >= 1000)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        cpu = per_window_cpu(args.windows, Path(tmp)) if args.windows > 0 else None
        if cpu:
            print(json.dumps(cpu, indent=1), flush=True)
        mem = memory(max(1000, args.estimates), Path(tmp))
    result = {"cpu": cpu, "memory": mem, "load_average": list(os.getloadavg()),
              "date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime())}
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "bench_year.json").write_text(json.dumps(result, indent=2))
    print(json.dumps(result, indent=2))
    return 0 if (cpu is None or cpu["met"]) and mem["met"] else 1


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    sys.exit(main())
