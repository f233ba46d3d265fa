"""Calibration of the time-domain explain threshold on clean event series (no amplitude effect, the
simulator's default model-form error): the largest evidence gain over the time-domain candidates per
replicate, and its 99th percentile (with fewer than 100 replicates: the largest value, said so).

    cd <repo> && PYTHONPATH=$PWD:$PWD/test OPENBLAS_NUM_THREADS=1 \\
        python test/td_threshold.py --replicates 100 --seed 2000 --jobs 2 \\
        --out shm_ros/core/explain/threshold_timedomain.json

``--more FILE --replicates N`` continues a run to N series (the same seeds, so the same result as a run
of N).

A candidate added to the set later needs only its own fits on the same replicates: ``--extend FILE
--candidates NAME`` runs NAME alone on the replicates recorded in FILE (same seeds) and keeps, per
replicate, the larger of the recorded largest gain and NAME's (the other candidates' fits do not depend
on NAME: each is compared with the same nominal model).
"""

from __future__ import annotations

import argparse
import json
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from explain_td_cases import event_series

from shm_ros.core.explain.timedomain import TD_CANDIDATES, TimeDomainConfig, explain_events
from shm_ros.core.structure import structure_from_dict


def replicate(seed: int, r: int, candidates: tuple[str, ...] = ()) -> tuple[float, str]:
    s = event_series(seed + r, None)
    cfg = TimeDomainConfig(threshold=1e9, seed=r)
    if candidates:
        cfg.candidates = candidates
    v = explain_events(s.events, structure_from_dict(s.structure), cfg)
    best = max(v.tried, key=lambda c: c.log_evidence_gain)
    print(f"replicate {r}: largest gain {best.log_evidence_gain:.2f} ({best.label})", flush=True)
    return float(best.log_evidence_gain), best.label


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--replicates", type=int, default=12)
    ap.add_argument("--seed", type=int, default=2000)
    ap.add_argument("--out", default="")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes")
    ap.add_argument("--summarize", default="", help="re-write the summary of a run's JSON (its gains and labels)")
    ap.add_argument("--extend", default="", help="a run's JSON to extend by the --candidates on its replicates")
    ap.add_argument("--candidates", default="", help="comma-separated candidates (with --extend)")
    ap.add_argument("--more", default="", help="a run's JSON to continue to --replicates series (same seeds)")
    a = ap.parse_args(argv)
    if a.more:
        return more(a)
    if a.summarize:  # e.g. after the statistic's definition changed: the replicates are not re-run
        return resummarize(a)
    if a.extend:
        return extend(a)
    t0 = time.time()
    runs: list[tuple[float, str]] = []
    out: dict = {}
    with ProcessPoolExecutor(max(a.jobs, 1)) as pool:
        for run in pool.map(replicate, [a.seed] * a.replicates, range(a.replicates)):
            runs.append(run)
            out = summary(runs, a, time.time() - t0)
            if a.out:  # after every replicate: a stopped run leaves what it has, marked provisional
                write(out, a.out)
    print(json.dumps(out, indent=2))
    return out


def extend(a: argparse.Namespace) -> dict:
    """The run in ``a.extend`` with ``a.candidates`` added (module doc)."""
    with open(a.extend) as f:
        old = json.load(f)
    cands = tuple(c for c in a.candidates.split(",") if c)
    if not cands:
        raise SystemExit("--extend needs --candidates")
    n, seed = int(old["replicates"]), int(old["seed"])
    t0 = time.time()
    new: list[tuple[float, str]] = []
    with ProcessPoolExecutor(max(a.jobs, 1)) as pool:
        for run in pool.map(replicate, [seed] * n, range(n), [cands] * n):
            new.append(run)
    runs = [(g, lab) if g >= gn else (gn, ln)
            for g, lab, (gn, ln) in zip(old["gains"], old["labels"], new, strict=True)]
    a.replicates, a.seed = n, seed
    out = summary(runs, a, old["wall_s_per_replicate"] * n / a.jobs + time.time() - t0)
    out["command"] = old["command"]
    # (a run written before the set was recorded tried the two amplitude candidates of its day)
    base = old.get("candidates", ["amplitude_stiffness", "amplitude_damping"])
    out["candidates"] = [*base, *(c for c in cands if c not in base)]
    out["extended"] = [*old.get("extended", []), {
        "candidates": list(cands), "gains": [round(g, 2) for g, _ in new],
        "command": f"PYTHONPATH=$PWD:$PWD/test OPENBLAS_NUM_THREADS=1 python test/td_threshold.py --extend "
                   f"<the run's JSON> --candidates {','.join(cands)} --jobs {a.jobs}",
        "wall_s_per_replicate": round((time.time() - t0) * a.jobs / n, 1)}]
    write(out, a.out or a.extend)
    print(json.dumps({k: v for k, v in out.items() if k not in ("gains", "labels")}, indent=2))
    return out


def more(a: argparse.Namespace) -> dict:
    """The run in ``a.more`` continued to ``a.replicates`` series: replicate ``r`` depends only on
    ``seed + r``, so the result is the run ``--replicates N`` would have made (module doc)."""
    with open(a.more) as f:
        old = json.load(f)
    if "extended" in old:
        raise SystemExit("--more needs a run of every candidate (not one extended by --extend)")
    n, a.seed = int(old["replicates"]), int(old["seed"])
    t0 = time.time()
    runs = list(zip(old["gains"], old["labels"], strict=True))
    with ProcessPoolExecutor(max(a.jobs, 1)) as pool:
        for run in pool.map(replicate, [a.seed] * (a.replicates - n), range(n, a.replicates)):
            runs.append(run)
            out = summary(runs, a, old["wall_s_per_replicate"] * n / a.jobs + time.time() - t0)
            out["provisional"] = len(runs) < a.replicates
            write(out, a.out or a.more)
    print(json.dumps({k: v for k, v in out.items() if k not in ("gains", "labels")}, indent=2))
    return out


def resummarize(a: argparse.Namespace) -> dict:
    """The summary of the run recorded in ``a.summarize`` again, from its gains (and labels: a run
    written before labels were kept has only their counts, so its output has only the counts too)."""
    with open(a.summarize) as f:
        old = json.load(f)
    labels = old.get("labels") or [k for k, n in old["argmax_counts"].items() for _ in range(n)]
    a.replicates, a.seed, a.jobs = old["replicates"], old["seed"], old.get("jobs", 2)
    out = summary(list(zip(old["gains"], labels, strict=True)), a,
                  old["wall_s_per_replicate"] * len(labels) / a.jobs)
    out["command"] = old["command"]
    for key in ("extended", "candidates"):
        if key in old:
            out[key] = old[key]
    if "labels" not in old:
        del out["labels"]
    write(out, a.out or a.summarize)
    return out


def summary(runs: list[tuple[float, str]], a: argparse.Namespace, wall_s: float) -> dict:
    gains = [g for g, _ in runs]
    argmax: dict[str, int] = {}
    for _, label in runs:
        argmax[label] = argmax.get(label, 0) + 1
    g = np.array(gains)
    q99 = float(np.quantile(g, 0.99)) if g.size >= 100 else float(g.max())
    # the percentile's sampling spread: bootstrap over the replicates
    boot = np.quantile(np.random.default_rng(0).choice(g, (2000, g.size)), 0.99, axis=1)
    thr = round(max(q99, 0.0), 2)
    return {"log_bayes_factor": thr, "provisional": g.size < 100,
            "statistic": "99th percentile over clean event series of the largest evidence gain over the "
                         "time-domain candidates (fewer than 100 replicates: their largest value)",
            "command": f"PYTHONPATH=$PWD:$PWD/test OPENBLAS_NUM_THREADS=1 python test/td_threshold.py "
                       f"--replicates {a.replicates} --seed {a.seed} --jobs {a.jobs}",
            "candidates": list(TD_CANDIDATES), "replicates": int(g.size), "seed": a.seed, "jobs": a.jobs, "events": 6,
            "percentile_interval_90": [round(float(x), 2) for x in np.quantile(boot, [0.05, 0.95])],
            "above_threshold": int(np.sum(g > thr)),
            "gains": [round(x, 2) for x in gains], "labels": [label for _, label in runs],
            "max_gain_quantiles": {"0.5": round(float(np.median(g)), 2), "max": round(float(g.max()), 2)},
            "argmax_counts": argmax, "wall_s_per_replicate": round(wall_s * a.jobs / max(g.size, 1), 1)}


def write(out: dict, path: str) -> None:
    with open(path, "w") as f:
        json.dump(out, f, indent=2)
        f.write("\n")


if __name__ == "__main__":
    main()
