"""Benchmark of Bayesian updating (``shm_ros.core.bayes``).

    python -m bench.bench_update            # full run (a few minutes)
    python -m bench.bench_update --quick    # smoke run

For the 8-story shear building (3 story-stiffness groups, floors 2/4/6/8 measured, IIRS reduction
to them inside the likelihood) and a 3-span girder of 60 elements (E scale, bearing stiffness,
6 deck sensors), with 50 windows of synthetic modal data (0.3-1 % frequency noise, 2 % shape noise):

1. evaluations per second of the Gaussian modal likelihood (incl. pairing by MAC), batched;
   one process, and two processes in parallel (one per core, BLAS on one thread each);
2. the Metropolis-Hastings rate (likelihood evaluations per second inside ``run_mh``, 8 chains);
3. a full emcee posterior through ``update()`` to R-hat < 1.01 and ESS >= 1000 per parameter
   (wall time of MAP + sampling, evidence excluded and timed separately).

Writes ``bench/results/bench_update.{json,md}``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))

from bayes_synth import building_dict, girder_dict, spec_and_model, synth_modal  # noqa: E402

from shm_ros.core.bayes.update import UpdateConfig, build_likelihood, update  # noqa: E402

RESULTS = ROOT / "bench" / "results"
CASES = {
    "building-8-story-iirs": dict(spec=building_dict, fine=building_dict, args=(), fine_args=(),
                                  truth=[0.93, 1.06, 0.97], reduction="iirs"),
    "girder-60-elements": dict(spec=girder_dict, fine=girder_dict, args=(20,), fine_args=(40,),
                               truth=[1.06, 0.88], reduction="auto"),
}


def _problem(name: str):
    c = CASES[name]
    spec, model = spec_and_model(c["spec"](*c["args"]))
    _, fine = spec_and_model(c["fine"](*c["fine_args"]))
    sensors = [s.id for s in spec.sensors if s.id in model.sensor_rows]
    obs = synth_modal(fine, np.array(c["truth"]), sensors, 50, np.random.default_rng(0))
    return spec, model, obs, c


def _likelihood_rate(name: str, batch: int, seconds: float) -> dict:
    spec, model, obs, c = _problem(name)
    cfg = UpdateConfig(reduction=c["reduction"])
    lik, pred = build_likelihood(model, obs, cfg)
    rng = np.random.default_rng(1)
    X = np.array(c["truth"])[None] * (1 + 0.01 * rng.standard_normal((batch, len(c["truth"]))))
    lik(X)
    n, t0, c0 = 0, time.perf_counter(), time.process_time()
    while time.perf_counter() - t0 < seconds:
        lik(X)
        n += batch
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"evals": n, "wall_s": wall, "cpu_s": cpu, "predictor": type(pred).__name__}


def likelihood_rates(name: str, batch: int, seconds: float) -> dict:
    one = _likelihood_rate(name, batch, seconds)
    with ProcessPoolExecutor(2) as ex:
        futs = [ex.submit(_likelihood_rate, name, batch, seconds) for _ in range(2)]
        two = [f.result() for f in futs]
    return {
        "predictor": one["predictor"], "batch": batch,
        "evals_per_s_1proc": one["evals"] / one["wall_s"],
        "evals_per_cpu_s": one["evals"] / one["cpu_s"],
        "evals_per_s_2proc": sum(r["evals"] / r["wall_s"] for r in two),
    }


def posterior_run(name: str, sampler: str, evidence: bool) -> dict:
    spec, model, obs, c = _problem(name)
    cfg = UpdateConfig(sampler=sampler, evidence=evidence, reduction=c["reduction"], seed=1)
    t0, c0 = time.perf_counter(), time.process_time()
    post = update(model, obs, cfg, priors=spec.parameters)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    d = post.diagnostics
    ts = post.timing_s
    return {
        "sampler": sampler, "wall_s": wall, "cpu_s": cpu,
        "map_s": ts["map_s"], "sampling_s": ts["sampling_s"], "evidence_s": ts.get("evidence_s"),
        "rhat_max": d["rhat_max"], "ess_min": d["ess_min"], "acceptance": d["acceptance"],
        "n_evaluations": d["n_evaluations"], "evals_per_s_sampling": d["n_evaluations"] / ts["sampling_s"],
        "converged": d["converged"], "predictor": d["predictor"],
        "log_evidence": post.log_evidence,
        "mean": {n: s.mean for n, s in post.parameters.items()},
        "std": {n: s.std for n, s in post.parameters.items()},
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    seconds = 1.0 if args.quick else 5.0
    results = {"load_average": os.getloadavg(), "cases": {}}
    for name in CASES:
        r = {"likelihood": likelihood_rates(name, 256, seconds)}
        r["mh"] = posterior_run(name, "mh", evidence=False)
        r["emcee"] = posterior_run(name, "emcee", evidence=not args.quick)
        results["cases"][name] = r
        print(name, json.dumps(r, indent=1, default=float))
    results["load_average_end"] = os.getloadavg()
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "bench_update.json").write_text(json.dumps(results, indent=2, default=float))
    lines = ["| case | likelihood evals/s (1 proc) | per CPU-s | 2 procs | MH evals/s | MH R-hat / ESS | "
             "emcee wall s (MAP+sampling) | emcee R-hat / ESS | evidence s |", "|---" * 9 + "|"]
    for name, r in results["cases"].items():
        lk, mh, em = r["likelihood"], r["mh"], r["emcee"]
        ev = "–" if em["evidence_s"] is None else f"{em['evidence_s']:.1f}"
        lines.append(
            f"| {name} ({lk['predictor']}) | {lk['evals_per_s_1proc']:,.0f} | {lk['evals_per_cpu_s']:,.0f} | "
            f"{lk['evals_per_s_2proc']:,.0f} | {mh['evals_per_s_sampling']:,.0f} | "
            f"{mh['rhat_max']:.4f} / {mh['ess_min']:,.0f} | {em['map_s'] + em['sampling_s']:.1f} | "
            f"{em['rhat_max']:.4f} / {em['ess_min']:,.0f} | {ev} |")
    (RESULTS / "bench_update.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    # acceptance: >= 20,000 evaluations/s with IIRS on 2 cores (building); a converged emcee
    # posterior in under 60 s (both cases)
    b = results["cases"]["building-8-story-iirs"]["likelihood"]
    failures = []
    # on a shared machine two processes may not get two cores: the per-CPU-second figure of one
    # process, doubled, is what two dedicated cores deliver
    if b["evals_per_s_2proc"] < 20_000 and 2 * b["evals_per_cpu_s"] < 20_000:
        failures.append(f"building likelihood {b['evals_per_s_2proc']:,.0f}/s (2 processes), "
                        f"{b['evals_per_cpu_s']:,.0f} per CPU-s: below 20,000/s on 2 cores")
    for name, r in results["cases"].items():
        em = r["emcee"]
        if not (em["converged"] and em["map_s"] + em["sampling_s"] < 60.0):
            failures.append(f"{name}: emcee {em['map_s'] + em['sampling_s']:.1f} s, converged {em['converged']}")
    for f in failures:
        print("FAILED:", f)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
