"""Throughput of reduced-model modal evaluations (IIRS) for the likelihood of model updating.

    python -m bench.bench_models            # about a minute
    python -m bench.bench_models --quick    # a few seconds (smoke run)

Measures, for the 8-story shear building of ``examples/building.yaml`` reduced to its four measured
floors: parameter vectors drawn from the file's priors -> K(theta), M(theta) -> IIRS -> reduced
modes (frequencies and shapes at the sensors), in batches; the IIRS iteration at two tolerances and
its converged limit computed from the lowest eigenvectors (``method="limit"``); ``plain`` is the
iteration without the geometric extrapolation. Reports evaluations per second in one
process and in two processes (the two cores the project targets), the iterations needed and the
accuracy against the full model's eigen-solution. Also the 66-DOF girder for scale. Writes
``bench/results/bench_models.{json,md,png}``.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import platform
import time
from pathlib import Path

import numpy as np

from shm_ros.core.models import build_model
from shm_ros.core.models.reduction import reduce_model, single_threaded_blas
from shm_ros.io.structure import load_structure

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "results"
SENSORS = ["f1", "f3", "f6", "f8"]


def _draws(spec, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    cols = [np.clip(p.prior.frozen().rvs(size=n, random_state=rng), 0.4, None) for p in spec.parameters]
    return np.column_stack(cols)


def _reduce(model, thetas, sensors, tol, method):
    if method == "plain":  # the IIRS iteration without extrapolation, for comparison
        return reduce_model(model, thetas, sensors, tol=tol, accelerate=False)
    return reduce_model(model, thetas, sensors, tol=tol, method=method)


def _run_batches(args) -> tuple[int, float, float, int]:
    """Worker: evaluate ``n_batches`` batches; returns (evaluations, wall s, cpu s, max iterations)."""
    structure, sensors, thetas, n_batches, tol, method = args
    model = build_model(load_structure(structure))
    its = 0
    with single_threaded_blas():
        w0, c0 = time.perf_counter(), time.process_time()
        for _ in range(n_batches):
            red = _reduce(model, thetas, sensors, tol, method)
            sol = red.modes(4)
            its = max(its, red.iterations)
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    assert np.all(np.isfinite(sol.frequencies_hz))
    return n_batches * len(thetas), wall, cpu, its


def bench_building(quick: bool) -> list[dict]:
    structure = str(ROOT / "examples" / "building.yaml")
    spec = load_structure(structure)
    model = build_model(spec)
    batch = 2000
    n_batches = 2 if quick else 10
    rows = []
    for method, tol in (("plain", 1e-4), ("plain", 1e-6), ("iterate", 1e-4), ("iterate", 1e-6), ("limit", 0.0)):
        thetas = _draws(spec, batch, seed=1)
        # accuracy against the full model (lowest four modes)
        red = _reduce(model, thetas, SENSORS, tol, method)
        err = np.abs(red.modes(4).frequencies_hz / model.modes_batch(thetas, 4).frequencies_hz - 1)
        one = _run_batches((structure, SENSORS, thetas, n_batches, tol, method))
        ctx = mp.get_context("fork")
        halves = [_draws(spec, batch, seed=s) for s in (2, 3)]
        with ctx.Pool(2) as pool:
            pool.map(_run_batches, [(structure, SENSORS, h[:100], 1, tol, method) for h in halves])  # warm-up
            w0 = time.perf_counter()
            two = pool.map(_run_batches, [(structure, SENSORS, h, n_batches, tol, method) for h in halves])
            wall2 = time.perf_counter() - w0
        rows.append(
            {
                "model": "8-story shear building, 4 of 8 floors measured",
                "method": method,
                "tol": tol,
                "batch": batch,
                "max_iterations": int(max(one[3], *[t[3] for t in two])),
                "max_freq_error_modes_1_4": [float(e) for e in err.max(axis=0)],
                "converged": bool(red.converged),
                "evals_per_s_1_process": one[0] / one[1],
                "evals_per_cpu_s_1_process": one[0] / max(one[2], 1e-9),
                "evals_per_s_2_processes": sum(t[0] for t in two) / wall2,
                "evals_per_s_2_processes_inside_workers": sum(t[0] / t[1] for t in two),
            }
        )
    return rows


def bench_girder(quick: bool) -> dict:
    spec = load_structure(ROOT / "examples" / "girder.yaml")
    model = build_model(spec)
    thetas = _draws(spec, 100 if quick else 400, seed=4)
    with single_threaded_blas():
        w0 = time.perf_counter()
        red = reduce_model(model, thetas, tol=1e-6)
        sol = red.modes(5)
        w_red = time.perf_counter() - w0
        w0 = time.perf_counter()
        full = model.modes_batch(thetas, 5)
        w_full = time.perf_counter() - w0
    err = np.abs(sol.frequencies_hz / full.frequencies_hz - 1)
    return {
        "model": f"girder, {model.n_dof} DOFs, 5 deck sensors",
        "evals_per_s_iirs": len(thetas) / w_red,
        "evals_per_s_full_eigh": len(thetas) / w_full,
        "max_freq_error_modes_1_5": [float(e) for e in err.max(axis=0)],
        "iterations": int(red.iterations),
    }


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="small run (smoke test)")
    a = ap.parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    rows = bench_building(a.quick)
    girder = bench_girder(a.quick)
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    result = {
        "command": "python -m bench.bench_models" + (" --quick" if a.quick else ""),
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "load_avg_1min": load[0]},
        "building": rows,
        "girder": girder,
    }
    (OUT / "bench_models.json").write_text(json.dumps(result, indent=2))

    lines = [
        "| method | tol (eigenvalue) | max iterations | max freq. error modes 1-4 | evals/s 1 process | "
        "evals per CPU-s 1 process | evals/s 2 processes |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['method']} | {r['tol']:.0e} | {r['max_iterations']} | {max(r['max_freq_error_modes_1_4']):.1e} | "
            f"{r['evals_per_s_1_process']:,.0f} | {r['evals_per_cpu_s_1_process']:,.0f} | "
            f"{r['evals_per_s_2_processes']:,.0f} |"
        )
    lines.append("")
    lines.append(
        f"Girder ({girder['model']}): IIRS {girder['evals_per_s_iirs']:,.0f}/s, full eigh "
        f"{girder['evals_per_s_full_eigh']:,.0f}/s, max freq. error {max(girder['max_freq_error_modes_1_5']):.1e}."
    )
    lines.append(f"Load average during the run: {load[0]:.2f} on {os.cpu_count()} CPUs.")
    text = "\n".join(lines)
    (OUT / "bench_models.md").write_text(text + "\n")
    print(text)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 3.8))
    labels = [f"{r['method']}\n{r['tol']:.0e}" if r["method"] != "limit" else "limit" for r in rows]
    x = np.arange(len(rows))
    ax.bar(x - 0.2, [r["evals_per_s_1_process"] for r in rows], 0.4, label="1 process")
    ax.bar(x + 0.2, [r["evals_per_s_2_processes"] for r in rows], 0.4, label="2 processes")
    ax.axhline(20000, color="k", ls="--", lw=1, label="target 20,000/s")
    ax.set_xticks(x, labels)
    ax.set_ylabel("reduced modal evaluations / s")
    ax.set_title("IIRS, 8-story building, 4 measured floors")
    ax.legend()
    fig.tight_layout()
    fig.savefig(OUT / "bench_models.png", dpi=120)


if __name__ == "__main__":
    main()
