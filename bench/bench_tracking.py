"""Benchmark of tracking with the history store (``shm_ros.core.tracking`` + ``shm_ros.io.store``).

    python -m bench.bench_tracking                   # one year: 52,560 ten-minute windows
    python -m bench.bench_tracking --windows 5000    # a smaller run
    python -m bench.bench_tracking --profile 5000    # cProfile of N windows (top entries printed)

A campaign of modal estimates (12 channels of a 3-span girder, 7 beam modes with a freezing knee in
the deck stiffness under a yearly + daily temperature cycle with cold spells, missed modes, dropped
channels, a spurious mode in about a third of the windows) is fed window by window through the
online :class:`Tracker` and :class:`TrackStore.record`, as the track node does (node defaults:
144 training windows, a checkpoint every 100 windows, no retention). Reported: windows/s (wall and
CPU), peak RSS, RSS along the run (memory bounded: the growth must flatten), and whether the
first 2,000 windows' assignments equal the stored fingerprint of the reference version
(``FINGERPRINT_2000``: performance work must not change a result). Target: >= 1,000 windows/s.

Writes ``bench/results/bench_tracking.{json,md}``.
"""

from __future__ import annotations

import argparse
import cProfile
import hashlib
import io
import json
import os
import pstats
import resource
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from shm_ros.core.tracking import TrackedRow, Tracker, TrackingConfig  # noqa: E402
from shm_ros.core.types import ModalEstimate, Mode  # noqa: E402
from shm_ros.io.store import TrackStore  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results"
YEAR = 52_560  # ten-minute windows
INTERVAL_NS = 600 * 10**9
N_SENSORS = 12
BASE_HZ = np.array([1.9, 2.6, 3.8, 5.1, 6.4, 7.9, 9.7])
# sha256 of the first 2,000 windows' assignments (FINGERPRINT_WINDOWS at seed 0), made with the
# code before the performance work; see fingerprint()
FINGERPRINT_WINDOWS = 2000
FINGERPRINT_2000 = "ddf54ed4c4b8282f746d0cc43a0feb688025df1acab96727ac48119cb06ba734"


def campaign(n: int, seed: int = 0):
    """Modal estimates of ``n`` consecutive windows (a generator: the campaign is never held whole)."""
    rng = np.random.default_rng(seed)
    x = np.linspace(0.05, 0.95, N_SENSORS)
    shapes = np.array([np.sin((k // 2 + 1) * np.pi * x + (0.3 * np.pi if k % 2 else 0.0)) for k in range(7)])
    shapes /= np.abs(shapes).max(axis=1, keepdims=True)
    sensors = [f"ch{i:02d}" for i in range(N_SENSORS)]
    # freezing spells: six multi-day dips a year, drawn apart from the windows so that the first
    # windows of a short run are those of the year (the fingerprint compares them)
    spells = np.random.default_rng([seed, 1]).uniform(0, 365, size=6)
    for i in range(n):
        day = i / 144.0
        near = (day - spells + 182.5) % 365.0 - 182.5  # days from each spell, the same every year
        cold = -8.0 * float(np.sum(np.exp(-0.5 * (near / 2.5) ** 2)))
        t = 8.0 - 12.0 * np.cos(2 * np.pi * day / 365.0) + 5.0 * np.sin(2 * np.pi * day) + cold
        t = float(t + rng.normal(0, 0.3))
        stiff = 1.0 - 0.0015 * t + (0.012 * -t if t < 0 else 0.0)  # bilinear: stiffer when frozen
        f_true = BASE_HZ * np.sqrt(stiff)
        cols = np.flatnonzero(rng.uniform(size=N_SENSORS) > 0.03)
        modes = []
        for k in range(f_true.size):
            if rng.uniform() < 0.07:
                continue
            phi = shapes[k, cols] + rng.normal(0, 0.03, cols.size)
            phi = phi / np.abs(phi).max() * (1 if rng.uniform() < 0.5 else -1)
            modes.append(Mode(float(f_true[k] * (1 + rng.normal(0, 0.002))),
                              float(0.015 * np.exp(rng.normal(0, 0.25))), phi))
        if rng.uniform() < 0.35:
            phi = rng.normal(size=cols.size)
            modes.append(Mode(float(rng.uniform(3.0, 30.0)), 0.02, phi / np.abs(phi).max()))
        modes.sort(key=lambda m: m.frequency_hz)
        start = i * INTERVAL_NS
        yield ModalEstimate(f"w{i:06d}", start, start + INTERVAL_NS, [sensors[c] for c in cols], modes,
                            temperature_c=t, covariates={"rms_accel_m_s2": float(np.exp(rng.normal(-4, 0.5)))})


def _rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _digest(h, rows: list[TrackedRow]) -> None:
    for r in rows:
        h.update(r.window_id.encode())
        h.update(np.asarray(r.mode_numbers, np.int64).tobytes())
        h.update(np.nan_to_num(np.asarray(r.frequencies_hz, float), nan=-1.0).tobytes())
        h.update(np.nan_to_num(np.asarray(r.normalised_hz, float), nan=-1.0).round(12).tobytes())
        h.update(repr((r.novelty_alarm, r.unassigned, round(r.novelty_score, 9)
                       if np.isfinite(r.novelty_score) else None)).encode())


def run(n: int, store_dir: Path, seed: int = 0, samples: int = 20) -> dict:
    """Feed ``n`` windows through tracker + store; returns the figures (and the assignments' digest)."""
    tracker = Tracker(TrackingConfig(), training_windows=144)
    h = hashlib.sha256()
    rss: list[tuple[int, float]] = [(0, _rss_mb())]
    every = max(1, n // samples)
    gen_s = 0.0
    with TrackStore(store_dir / "track.sqlite", checkpoint_every=100) as store:
        t0, c0 = time.perf_counter(), time.process_time()
        it = campaign(n, seed)
        for i in range(n):
            g = time.perf_counter()
            est = next(it)
            gen_s += time.perf_counter() - g
            if store.has(est.window_id):  # as the node does
                continue
            rows = tracker.add(est)
            store.record(est, rows, tracker)
            if i < FINGERPRINT_WINDOWS:
                _digest(h, rows)
            if (i + 1) % every == 0:
                rss.append((i + 1, _rss_mb()))
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        stored = store.count("rows")
    db_mb = sum(p.stat().st_size for p in store_dir.iterdir()) / 2**20
    net = wall - gen_s
    return {"windows": n, "stored_rows": stored, "tracked_modes": len(tracker.reference),
            "wall_s": wall, "cpu_s": cpu, "generator_s": gen_s,
            "windows_per_s_wall": n / net, "windows_per_s_cpu": n / max(cpu - gen_s, 1e-9),
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "rss_mb": rss,
            "db_mb": db_mb, "fingerprint": h.hexdigest() if n >= FINGERPRINT_WINDOWS else None,
            "load_avg": os.getloadavg()}


def _growth(rss: list[tuple[int, float]]) -> tuple[float, float]:
    """RSS growth (MB) over the first and the second half of the run."""
    mid = len(rss) // 2
    return rss[mid][1] - rss[1][1], rss[-1][1] - rss[mid][1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.bench_tracking", description=__doc__.split("\n")[0])
    ap.add_argument("--windows", type=int, default=YEAR, help="windows to run (default one year, 52,560)")
    ap.add_argument("--profile", type=int, default=0, metavar="N", help="cProfile N windows instead")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    if args.profile:
        with tempfile.TemporaryDirectory() as d:
            prof = cProfile.Profile()
            prof.enable()
            run(args.profile, Path(d), args.seed)
            prof.disable()
        out = io.StringIO()
        pstats.Stats(prof, stream=out).sort_stats("tottime").print_stats(25)
        print(out.getvalue())
        return 0
    with tempfile.TemporaryDirectory() as d:
        res = run(args.windows, Path(d), args.seed)
    first, second = _growth(res["rss_mb"])
    same = None if res["fingerprint"] is None or args.seed != 0 else res["fingerprint"] == FINGERPRINT_2000
    res.update({"rss_growth_first_half_mb": first, "rss_growth_second_half_mb": second,
                "identical_to_reference": same, "meets_1000_per_s": res["windows_per_s_wall"] >= 1000})
    lines = [f"# bench_tracking ({res['windows']} windows, seed {args.seed})", "",
             f"- windows/s: {res['windows_per_s_wall']:.0f} wall, {res['windows_per_s_cpu']:.0f} CPU "
             f"(generator excluded: {res['generator_s']:.1f} s of {res['wall_s']:.1f} s)",
             f"- peak RSS {res['peak_rss_mb']:.0f} MB; RSS growth {first:+.1f} MB first half, "
             f"{second:+.1f} MB second half; store {res['db_mb']:.0f} MB",
             f"- tracked modes {res['tracked_modes']}, stored rows {res['stored_rows']}",
             f"- first {FINGERPRINT_WINDOWS} windows identical to the reference version: {same}",
             f"- load average at the end {tuple(round(x, 2) for x in res['load_avg'])}",
             f"- >= 1,000 windows/s: {'met' if res['meets_1000_per_s'] else 'NOT met'}"]
    print("\n".join(lines))
    if args.windows == YEAR:
        RESULTS.mkdir(exist_ok=True)
        (RESULTS / "bench_tracking.json").write_text(json.dumps(res, indent=1))
        (RESULTS / "bench_tracking.md").write_text("\n".join(lines) + "\n")
    return 0 if same is not False else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
