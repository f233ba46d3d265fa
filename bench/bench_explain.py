"""Benchmark of ``explain`` on an 8-day campaign's tracked-modes table (1,152 ten-minute windows).

    python -m bench.bench_explain                   # both cases, 1,152 windows
    python -m bench.bench_explain --windows 288     # a smaller run
    python -m bench.bench_explain --cases knee      # one case

Cases (``test/explain_cases.py``, ``draw_case``; girder, the simulator's default model-form error,
identification scatter, out-of-plane modes in the table):

* ``knee``: temperature-dependent stiffness with a knee (``form="bilinear"``);
* ``step``: a stiffness loss at a moment (on top of a mild linear temperature dependence).

Each runs the whole of ``explain`` with its defaults (baseline calibration, locate, every proposed
candidate fitted with its evidence by importance sampling and prior sensitivity, the nested-sampling
check for the accepted ones, the second round, the catch-all); the case generator's time is not
counted. Reported per case: wall and CPU time (this process; BLAS on one thread), time per stage
(from explain's progress callback), candidates fitted, the verdict against the case's truth.
Target: under 5 minutes per case on 2 cores.

Writes ``bench/results/bench_explain.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results"
TARGET_S = 300.0
CASES = {"knee": ("temperature_dependent_stiffness", "bilinear"), "step": ("stiffness_change_at_time", None)}


def _stage(label: str) -> str:
    """Progress labels -> stages: 'fit <candidate> on <group>' counts as 'fit', etc."""
    for prefix in ("baseline", "fit", "evidence check", "done"):
        if label.startswith(prefix):
            return "second round" if " on top of " in label else prefix
    return label


def run_case(name: str, seed: int, n_windows: int) -> dict[str, Any]:
    sys.path.insert(0, str(ROOT / "test"))
    from explain_cases import draw_case

    from shm_ros.core.explain.explain import explain
    from shm_ros.core.structure import structure_from_dict

    effect, form = CASES[name]
    t0 = time.perf_counter()
    case = draw_case(seed, effect, "girder", n_windows=n_windows, form=form)
    spec = structure_from_dict(case.structure)
    t_case = time.perf_counter() - t0
    stages: dict[str, float] = {}
    last_t, last_label = [time.perf_counter()], ["baseline"]

    def progress(label: str, frac: float) -> None:
        now = time.perf_counter()
        key = _stage(last_label[0])
        stages[key] = stages.get(key, 0.0) + now - last_t[0]
        if _stage(label) != key:  # a stage starts: say so (long runs)
            print(f"{name}: {label} at {now - w0:.0f} s wall, {time.process_time() - c0:.0f} s CPU",
                  file=sys.stderr, flush=True)
        last_t[0], last_label[0] = now, label

    w0, c0 = time.perf_counter(), time.process_time()
    v = explain(case.obs, spec, progress=progress)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    d = v.to_dict()
    truth = case.truth
    return {
        "case": name, "seed": seed, "windows": n_windows, "modes": int(case.obs.n_modes),
        "truth": {"name": truth.name, "where": truth.where, "size": truth.size, "knee_c": truth.knee_c,
                  "change_index": truth.change_index},
        "wall_s": round(wall, 1), "cpu_s": round(cpu, 1), "case_generation_s": round(t_case, 1),
        "stages_wall_s": {k: round(s, 1) for k, s in stages.items()},
        "candidates_fitted": len(d["candidates"]),
        "accepted": [{"label": m["label"], "form": m["form"], "log_evidence_gain": round(m["log_evidence_gain"], 1),
                      **({"change_window": m["change_window"]} if "change_window" in m else {})}
                     for m in d["missing_physics"] if m["name"] != "unmodelled_modes"],
        "unmodelled_modes": sum(m["name"] == "unmodelled_modes" for m in d["missing_physics"]),
        "unexplained": d.get("unexplained_structure", {}).get("summary"),
        "fit": d["fit"], "threshold": d["threshold"].get("log_bayes_factor"),
        "target_met": bool(wall < TARGET_S),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--windows", type=int, default=1152)
    ap.add_argument("--cases", nargs="+", choices=sorted(CASES), default=["knee", "step"])
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--out", default=str(RESULTS / "bench_explain.json"))
    a = ap.parse_args(argv)
    rows = []
    for name in a.cases:
        r = run_case(name, a.seed, a.windows)
        print(json.dumps(r, indent=1), flush=True)
        rows.append(r)
    out = {"command": "python -m bench.bench_explain " + " ".join(argv if argv is not None else sys.argv[1:]),
           "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "load_average": os.getloadavg(),
           "target_s": TARGET_S, "cases": rows}
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(out, indent=2) + "\n")
    return 0 if all(r["target_met"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
