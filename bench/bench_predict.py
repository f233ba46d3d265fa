"""Prediction cost: a 60 s event at 100 Hz pushed through the eight-story building with dampers
for 500 posterior draws (issue target: under 5 s on 2 cores), with the predictive band and peaks.
Reports wall and CPU time on one and on two threads (``PredictConfig.threads``; BLAS runs one
thread either way) and the load average, since the figures depend on what else the machine runs.

    python -m bench.bench_predict [--draws 500] [--fs 100] [--duration 60]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))


def main(argv: list[str]) -> int:
    from predict_synth import simulate_quakes

    from shm_ros.core.models import build_model
    from shm_ros.core.predict import PosteriorDraws, PredictConfig, event_from_window, predict_event
    from shm_ros.core.structure import structure_from_dict

    ap = argparse.ArgumentParser(prog="bench_predict")
    ap.add_argument("--draws", type=int, default=500)
    ap.add_argument("--fs", type=float, default=100.0)
    ap.add_argument("--duration", type=float, default=60.0)
    a = ap.parse_args(argv)
    q = simulate_quakes(0, 1, duration_s=a.duration, fs=a.fs)
    model = build_model(structure_from_dict(q.structure))
    ev = event_from_window(q.windows[0], model)
    rng = np.random.default_rng(0)
    th = model.nominal_theta() * (1 + 0.02 * rng.standard_normal((a.draws, model.n_parameters)))
    draws = PosteriorDraws(th, model.nominal_theta(), {}, 0.0025, "bench")
    wall: dict[int, float] = {}
    cpu: dict[int, float] = {}
    means = []
    load = os.getloadavg()
    for threads in (1, 2):
        t, c = time.perf_counter(), time.process_time()
        p = predict_event(model, ev, draws, PredictConfig(n_draws=a.draws, threads=threads))
        wall[threads], cpu[threads] = time.perf_counter() - t, time.process_time() - c
        means.append(np.stack([ch.mean for ch in p.channels]))
    same = float(np.max(np.abs(means[0] - means[1])))
    print(f"{a.duration:g} s at {a.fs:g} Hz ({ev.n_samples} samples), {a.draws} draws, {len(p.channels)} outputs; "
          f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores")
    for k in (1, 2):
        print(f"  {k} thread{'s' if k > 1 else ''}: {wall[k]:.2f} s wall, {cpu[k]:.2f} s CPU")
    print(f"  largest difference of the predictive means between 1 and 2 threads: {same:.1e}")
    return 0 if min(wall.values()) < 5.0 and same == 0.0 else 1


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
