"""Calibrate explain's acceptance threshold on clean replicates and write the shipped JSON.

    python -m bench.calibrate_explain --replicates 200 --windows 1152 \
        --out shm_ros/core/explain/threshold.json

Each replicate is a clean modal table (no hidden effect, the simulator's default model-form error:
test/explain_cases.py when present, else test/explain_engine_synth.py) run through ``explain`` with
every candidate fitted and nothing accepted; the statistic is the largest evidence gain over all
candidates of the replicate. The threshold is its ``--quantile`` (default 99 %) over the replicates,
so a clean campaign clears it by chance in about 1 % of cases. Replicates run in ``--jobs`` processes.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _clean_table(seed: int, n_windows: int):
    sys.path.insert(0, str(ROOT / "test"))
    try:
        import explain_cases

        obs, spec_dict, _ = explain_cases.clean_case(seed, n_windows)
        from shm_ros.core.structure import structure_from_dict

        return obs, structure_from_dict(spec_dict)
    except (ImportError, AttributeError):
        from explain_engine_synth import engine_table

        obs, spec, _ = engine_table(seed, n_windows, None)
        return obs, spec


def replicate(args: tuple[int, int]) -> float:
    from threadpoolctl import threadpool_limits

    from shm_ros.core.explain.config import ExplainConfig
    from shm_ros.core.explain.explain import explain

    seed, n_windows = args
    obs, spec = _clean_table(seed, n_windows)
    with threadpool_limits(1):
        v = explain(obs, spec, ExplainConfig(threshold=math.inf, nested_check=False, prior_sensitivity=False,
                                             n_importance=1500, seed=seed))
    return max(c.log_evidence_gain for c in v.tried)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--replicates", type=int, default=200)
    ap.add_argument("--windows", type=int, default=1152)
    ap.add_argument("--quantile", type=float, default=0.99)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--out", default=str(ROOT / "shm_ros/core/explain/threshold.json"))
    a = ap.parse_args(argv)
    t0 = time.time()
    seeds = [(a.seed + i, a.windows) for i in range(a.replicates)]
    with ProcessPoolExecutor(a.jobs) as pool:
        gains = np.array(list(pool.map(replicate, seeds)))
    thr = float(np.quantile(gains, a.quantile))
    out = {"log_bayes_factor": max(thr, 0.0), "provisional": False,
           "statistic": f"{100 * a.quantile:g}th percentile over clean replicates of the largest evidence "
                        "gain over all candidates",
           "command": f"python -m bench.calibrate_explain --replicates {a.replicates} --windows {a.windows}",
           "replicates": a.replicates, "windows": a.windows,
           "max_gain_quantiles": {q: float(np.quantile(gains, float(q))) for q in ("0.5", "0.9", "0.99")},
           "seconds": round(time.time() - t0, 1)}
    Path(a.out).write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
