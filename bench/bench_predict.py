"""Prediction cost: a 60 s event at 100 Hz pushed through the eight-story building with dampers
for 500 posterior draws (issue target: under 5 s on 2 cores), with the predictive band and peaks.

    python -m bench.bench_predict [--draws 500] [--fs 100] [--duration 60]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))


def main(argv: list[str]) -> int:
    from predict_synth import simulate_quakes
    from threadpoolctl import threadpool_limits

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
    cfg = PredictConfig(n_draws=a.draws)
    out = {}
    for threads in (1, 2):
        with threadpool_limits(threads):
            t = time.perf_counter()
            p = predict_event(model, ev, draws, cfg)
            out[threads] = time.perf_counter() - t
    print(f"{a.duration:g} s at {a.fs:g} Hz ({ev.n_samples} samples), {a.draws} draws, "
          f"{len(p.channels)} outputs: {out[1]:.2f} s on 1 BLAS thread, {out[2]:.2f} s on 2")
    return 0 if min(out.values()) < 5.0 else 1


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
