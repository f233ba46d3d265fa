"""Offline ingest throughput: bag -> IngestCore -> windows (read + decode + check + cut).

    python -m bench.bench_ingest                         # 120 s x 16 channels x 200 Hz
    python -m bench.bench_ingest --seconds 600 --window 600   # one 10-minute window

Bags: per-sample ``sensor_msgs/Imu`` (16 topics, jittered stamps, written in 0.5 s slices as a
recorder interleaves them) and ``AccelBlock`` (0.5 s blocks), each as zstd MCAP and as sqlite3.
Writes ``bench/results/bench_ingest.{json,md}``; the figure is channel samples per second of wall
time (best of ``--repeat``), target >= 200,000.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

T0 = 1_714_521_600_000_000_000


def write_bag(path: Path, layout: str, storage: str, seconds: float, channels: int, fs: float) -> int:
    from shm_ros.io.bags import BagWriter

    rng = np.random.default_rng(0)
    n = int(seconds * fs)
    period = int(round(1e9 / fs))
    grid = T0 + np.arange(n, dtype=np.int64) * period
    x = rng.standard_normal((n, channels)) * 0.01
    x[:, 0] += 9.81
    step = int(0.5 * fs)
    with BagWriter(path, storage=storage, compress=(storage == "mcap")) as w:
        if layout == "imu":
            stamps = [grid + rng.integers(-period // 5, period // 5, n) for _ in range(channels)]
            for s in stamps:
                s[0] = grid[0]
            for i in range(0, n, step):
                sl = slice(i, min(n, i + step))
                for c in range(channels):
                    xyz = np.zeros((sl.stop - sl.start, 3))
                    xyz[:, 2] = x[sl, c]
                    w.imu_series(f"/bench/accel/s{c}", stamps[c][sl], xyz, receive_ns=grid[sl] + 2_000_000)
        else:
            names = [f"s{c}" for c in range(channels)]
            for i in range(0, n, step):
                w.accel_block("/bench/daq/accel_block", int(grid[i]), fs, names, x[i:i + step])
    return n * channels


def run(seconds: float = 120.0, window: float = 60.0, channels: int = 16, fs: float = 200.0,
        repeat: int = 3, storages: tuple[str, ...] = ("mcap", "sqlite3")) -> dict:
    from shm_ros.core.ingest import ChannelMap
    from shm_ros.io.recording import ingest_bag

    cmap = ChannelMap.simple([f"s{c}" for c in range(channels)])
    tmp = Path(tempfile.mkdtemp(prefix="shm_bench_ingest_"))
    rows = []
    try:
        ingest_bag(Path("/nonexistent"), cmap, window_s=window)  # imports done outside the timing
        for layout in ("imu", "block"):
            for storage in storages:
                bag = tmp / f"{layout}_{storage}"
                samples = write_bag(bag, layout, storage, seconds, channels, fs)
                size = sum(f.stat().st_size for f in bag.iterdir())
                walls, cpus = [], []
                for _ in range(repeat):
                    t0, c0 = time.perf_counter(), time.process_time()
                    res = ingest_bag(bag, cmap, window_s=window)
                    walls.append(time.perf_counter() - t0)
                    cpus.append(time.process_time() - c0)
                    assert res.stats.samples_windowed == samples, (layout, storage, res.stats)
                best = min(walls)
                rows.append({
                    "layout": layout, "storage": storage + ("+zstd" if storage == "mcap" else ""),
                    "messages": res.messages, "channel_samples": samples, "windows": len(res.windows),
                    "bag_mb": round(size / 1e6, 1), "wall_s_best": round(best, 3),
                    "wall_s_median": round(float(np.median(walls)), 3), "cpu_s_best": round(min(cpus), 3),
                    "samples_per_s": int(samples / best), "samples_per_cpu_s": int(samples / min(cpus)),
                })
                shutil.rmtree(bag)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {
        "seconds": seconds, "window_s": window, "channels": channels, "sample_rate_hz": fs, "repeat": repeat,
        "rows": rows, "max_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "cpu_count": os.cpu_count(), "load_average": [round(v, 2) for v in os.getloadavg()],
        "python": platform.python_version(),
    }


def to_markdown(r: dict) -> str:
    lines = [
        f"{r['seconds']:g} s x {r['channels']} channels x {r['sample_rate_hz']:g} Hz, windows of "
        f"{r['window_s']:g} s; best of {r['repeat']}; load average {r['load_average']}; "
        f"peak RSS {r['max_rss_mb']} MB",
        "",
        "| layout | storage | messages | bag MB | wall s (best / median) | CPU s | samples/s (wall) | samples per CPU-s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in r["rows"]:
        lines.append(f"| {row['layout']} | {row['storage']} | {row['messages']:,} | {row['bag_mb']} | "
                     f"{row['wall_s_best']} / {row['wall_s_median']} | {row['cpu_s_best']} | "
                     f"{row['samples_per_s']:,} | {row['samples_per_cpu_s']:,} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seconds", type=float, default=120.0)
    p.add_argument("--window", type=float, default=60.0)
    p.add_argument("--channels", type=int, default=16)
    p.add_argument("--fs", type=float, default=200.0)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    a = p.parse_args(argv)
    r = run(a.seconds, a.window, a.channels, a.fs, a.repeat)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench_ingest.json").write_text(json.dumps(r, indent=1))
    md = to_markdown(r)
    (out / "bench_ingest.md").write_text(md)
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
