"""Time and size of writing the 8-day girder campaign (1,152 windows x 600 s, 100 Hz, 9 channels,
AccelBlock, MCAP with zstd chunk compression).

    python -m bench.bench_simulate                 # full size
    python -m bench.bench_simulate --windows 24    # a slice, figures extrapolated to 1,152 windows

Writes ``bench/results/bench_simulate.json`` with the figures.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

FULL_WINDOWS = 1152


def run(n_windows: int = FULL_WINDOWS, window_s: float = 600.0, workers: int = 1, out_dir: str | None = None,
        keep: bool = False, progress: bool = True) -> dict:
    from shm_ros.core.simulate import named_scenario, simulate_campaign
    from shm_ros.io.campaign import print_progress, write_campaign

    sc = named_scenario("girder", n_windows=n_windows, window_s=window_s, seed=2024, output="block",
                        storage="mcap", compress=True)
    tmp = Path(out_dir) if out_dir else Path(tempfile.mkdtemp(prefix="shm_bench_sim_"))
    target = tmp / "campaign"
    if target.exists():
        shutil.rmtree(target)
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    campaign = simulate_campaign(sc)
    files = write_campaign(campaign, target, workers=workers,
                           progress=print_progress(max(1, n_windows // 20)) if progress else None)
    wall = time.perf_counter() - t0
    truth_bytes = files.truth.stat().st_size
    samples = n_windows * round(window_s * sc.fs) * len(campaign.sensor_ids)
    result = {
        "n_windows": n_windows,
        "window_s": window_s,
        "sample_rate_hz": sc.fs,
        "channels": len(campaign.sensor_ids),
        "samples": samples,
        "workers": workers,
        "wall_s": round(wall, 2),
        "main_process_cpu_s": round(time.process_time() - cpu0, 2),
        "bag_bytes": files.bag_bytes,
        "bag_bytes_per_sample": round(files.bag_bytes / samples, 3),
        "truth_json_bytes": truth_bytes,
        "wall_s_per_window": round(wall / n_windows, 4),
        "extrapolated_full_wall_s": round(wall / n_windows * FULL_WINDOWS * 600.0 / window_s, 1),
        "extrapolated_full_bag_gb": round(files.bag_bytes / n_windows * FULL_WINDOWS * 600.0 / window_s / 1e9, 2),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
    }
    if not keep and out_dir is None:
        shutil.rmtree(tmp, ignore_errors=True)
    return result


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--windows", type=int, default=FULL_WINDOWS)
    ap.add_argument("--window-s", type=float, default=600.0)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--out", help="keep the campaign here (default: a temporary folder, deleted)")
    args = ap.parse_args(argv)
    res = run(args.windows, args.window_s, args.workers, args.out, keep=args.out is not None)
    out = Path(__file__).resolve().parent / "results"
    out.mkdir(exist_ok=True)
    (out / "bench_simulate.json").write_text(json.dumps(res, indent=1))
    print(json.dumps(res, indent=1))
    print(f"simulate: {res['n_windows']} windows in {res['wall_s']:.1f} s, bag {res['bag_bytes'] / 1e9:.2f} GB "
          f"(full campaign: ~{res['extrapolated_full_wall_s'] / 60:.1f} min, ~{res['extrapolated_full_bag_gb']:.2f} GB)",
          file=sys.stderr)
    # target: the full campaign written in under 10 minutes (checked here, not in the tests)
    if res["extrapolated_full_wall_s"] > 600.0:
        print(f"FAILED: full campaign ~{res['extrapolated_full_wall_s']:.0f} s, target 600 s", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
