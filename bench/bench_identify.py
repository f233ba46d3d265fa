"""Benchmark of ``identify``: SSI-cov and SSI-data against pyOMA2 (same run, same window).

One 12-channel x 60,000-sample window (10 min at 100 Hz) of the test-side simulator
(``test/synthetic_oma.py``: 36-DOF building, non-proportional damping, coloured non-stationary
forcing, 2 % sensor noise, gravity offsets, drift), 40 block rows, model orders 1..100 step 1,
uncertainty off. Timed (median of ``--repeat`` rounds in which the tools take turns, wall and
CPU seconds): the whole call from raw window to modal estimate (ours: pre-processing,
subspace step, poles of all orders with both estimates of A, stability, automatic picking;
pyOMA2: ``SingleSetup.run_by_name`` = Hankel matrix, SVD, poles of all orders, stability labels,
plus ``mpe`` with the TRUE frequencies given as the selection). Peak memory: tracemalloc peak of
a separate, untimed run. Accuracy of modes 1-4 against the simulator's eigenvalues.

Then the campaign: 1,152 such windows (8 distinct simulated windows, cycled) identified by two
worker processes (BLAS on one thread each), SSI-cov and SSI-data.

    python -m bench.bench_identify            # full run (about 15 minutes)
    python -m bench.bench_identify --accuracy-windows 24   # accuracy over 24 windows
    python -m bench.bench_identify --quick    # smoke run: 2 min window, 24-window campaign
    python -m bench.bench_identify --methods ssi-cov --campaign 0   # SSI-cov table only
                                              # (writes bench_identify_ssi-cov.{json,md})
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time
import tracemalloc
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))

import synthetic_oma as so  # noqa: E402

from shm_ros.core.identify import IdentifyConfig, identify_window  # noqa: E402
from shm_ros.core.types import Window  # noqa: E402

RESULTS = ROOT / "bench" / "results"
BLOCK_ROWS = 40
MAX_ORDER = 100
FS = 100.0
N_CH = 12


def _config(method: str, weighting: str = "pc") -> IdentifyConfig:
    # band "off": the block rows and the rate are fixed here, as they are for pyOMA2, so the
    # automatic band of interest (an output spectrum that would only confirm them) is not run
    return IdentifyConfig(method=method, block_rows=BLOCK_ROWS, max_order=MAX_ORDER, min_order=1,
                          order_step=1, uncertainty=False, weighting=weighting, band="off")


def _window(seed: int, duration: float) -> tuple[Window, so.Truth]:
    y, fs, truth, names = so.ambient_record(seed, duration=duration, fs=FS, noise=0.02,
                                            n_sensors=N_CH)
    return Window(f"bench{seed}", 0, fs, names, np.array(y)), truth


def _ours(window: Window, method: str, weighting: str = "pc"):
    est = identify_window(window, _config(method, weighting))
    f = np.array([m.frequency_hz for m in est.modes])
    z = np.array([m.damping_ratio for m in est.modes])
    phi = [m.mode_shape for m in est.modes]
    return f, z, phi


def _pyoma(window: Window, method: str, sel_freq: list[float]):
    from pyoma2.algorithms import SSI
    from pyoma2.setup import SingleSetup

    data = window.samples - window.samples.mean(axis=0)  # pyOMA2 does not remove offsets
    setup = SingleSetup(data, window.sample_rate_hz)
    alg = SSI(name="alg", method="cov" if method == "ssi-cov" else "dat", br=BLOCK_ROWS,
              ordmax=MAX_ORDER, step=1, calc_unc=False)
    setup.add_algorithms(alg)
    setup.run_by_name("alg")
    setup.mpe("alg", sel_freq=sel_freq, order_in="find_min")
    r = alg.result
    assert r is not None, "pyOMA2 returned no result"
    phi = np.asarray(r.Phi)
    return (np.asarray(r.Fn, float), np.asarray(r.Xi, float),
            [real for real in (np.real(phi[:, k] * np.exp(-0.5j * np.angle(np.sum(phi[:, k] ** 2))))
                               for k in range(phi.shape[1]))])


def _accuracy(truth: so.Truth, f, z, phi) -> list[dict]:
    rows: list[dict[str, bool | float]] = []
    for k in range(4):
        if f.size == 0:
            rows.append({"found": False})
            continue
        j = int(np.argmin(np.abs(f - truth.frequency_hz[k])))
        rel = abs(f[j] / truth.frequency_hz[k] - 1)
        if rel > 0.05:
            rows.append({"found": False})
            continue
        rows.append({"found": True, "f_err_pct": 100 * rel,
                     "z_err_pct": 100 * abs(z[j] / truth.damping_ratio[k] - 1),
                     "mac": so.mac_real(truth.shapes[k], np.asarray(phi[j], float))})
    return rows


def _pool(per_window: list[list[dict]]) -> list[dict]:
    """Per mode over the windows: detection rate, mean |frequency error| %, mean |damping error| %,
    mean MAC (over the windows where the mode was found)."""
    out = []
    for k in range(4):
        found = [w[k] for w in per_window if w[k].get("found")]
        if not found:
            out.append({"found": False, "rate": 0.0})
            continue
        out.append({"found": True, "rate": len(found) / len(per_window),
                    "f_err_pct": float(np.mean([a["f_err_pct"] for a in found])),
                    "z_err_pct": float(np.mean([a["z_err_pct"] for a in found])),
                    "mac": float(np.mean([a["mac"] for a in found]))})
    return out


def paired_frequency_difference(ours: list[list[float | None]], peer: list[list[float | None]]
                                ) -> list[dict[str, float | int]]:
    """Per mode, over the windows where both tools found it: the mean of (our |frequency error| -
    the peer's) in points of %, its standard error, and the window count. Both tools see the same
    windows, so the difference is free of the windows' own scatter; ``equal_or_smaller``: the mean
    difference is below two standard errors (no larger error shown)."""
    out = []
    for k in range(len(ours[0]) if ours else 0):
        d = np.array([o[k] - p[k] for o, p in zip(ours, peer, strict=True)
                      if o[k] is not None and p[k] is not None])
        se = float(d.std(ddof=1) / np.sqrt(d.size)) if d.size > 1 else float("nan")
        mean = float(d.mean()) if d.size else float("nan")
        out.append({"mean": mean, "se": se, "windows": int(d.size), "equal_or_smaller": bool(mean < 2 * se)})
    return out


def _once(fn, *args) -> tuple[object, float, float]:
    """One call: its result, wall and CPU seconds (CPU: one BLAS thread; the fairer measure on a
    shared machine)."""
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn(*args)
    return out, time.perf_counter() - t0, time.process_time() - c0


def _peak(fn, *args) -> float:
    """tracemalloc peak (MiB) of one more, untimed run."""
    tracemalloc.start()
    fn(*args)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak / 2 ** 20


# ---------------------------------------------------------------------------- campaign workers
_WINDOWS: list[Window] = []


def _init(windows: list[Window]) -> None:
    global _WINDOWS
    _WINDOWS = windows


def _work(args: tuple[int, str]) -> tuple[int, float]:
    k, method = args
    t0 = time.process_time()
    est = identify_window(_WINDOWS[k % len(_WINDOWS)], _config(method))
    return len(est.modes), time.process_time() - t0


def campaign(windows: list[Window], n: int, method: str, workers: int = 2) -> dict:
    t0 = time.perf_counter()
    with ProcessPoolExecutor(workers, initializer=_init, initargs=(windows,)) as pool:
        out = list(pool.map(_work, [(k, method) for k in range(n)], chunksize=8))
    wall = time.perf_counter() - t0
    cpu = float(sum(c for _, c in out))
    return {"method": method, "windows": n, "workers": workers, "wall_s": wall,
            "per_window_s": wall / n, "mean_modes": float(np.mean([m for m, _ in out])),
            "cpu_s": cpu, "extrapolated_1152_s": wall / n * 1152,
            "dedicated_2core_1152_s": cpu / n * 1152 / workers}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="short window and small campaign")
    ap.add_argument("--campaign", type=int, default=None,
                    help="campaign size (default 1152; 0 skips the campaign)")
    ap.add_argument("--methods", nargs="+", choices=["ssi-cov", "ssi-data"],
                    default=["ssi-cov", "ssi-data"], help="methods to compare (default both)")
    ap.add_argument("--seed", type=int, default=2024)
    ap.add_argument("--repeat", type=int, default=5,
                    help="timing rounds on the first window (median reported; default 5)")
    ap.add_argument("--accuracy-windows", type=int, default=8,
                    help="windows (seeds seed, seed+1, ...) over which accuracy is averaged "
                         "(default 8; the campaign cycles the first 8)")
    args = ap.parse_args(argv)
    logging.disable(logging.WARNING)  # pyOMA2 logs every step at INFO
    duration = 120.0 if args.quick else 600.0
    n_campaign = args.campaign if args.campaign is not None else (24 if args.quick else 1152)
    methods = [m for m in ("ssi-cov", "ssi-data") if m in args.methods]
    RESULTS.mkdir(parents=True, exist_ok=True)

    windows = [_window(args.seed + k, duration) for k in range(max(1, args.accuracy_windows))]
    window, truth = windows[0]
    rows = []
    for method in methods:
        # SSI-data: ours with its default PC weighting and with the unweighted (UPC) form that
        # pyOMA2's SSIdat uses
        tools = (["shm_ros", "shm_ros (UPC)"] if method == "ssi-data" else ["shm_ros"]) + [
            "pyOMA2 1.4.3"]

        def call(tool: str, w: Window, tr: so.Truth, method: str = method) -> Callable[[], tuple]:
            if tool.startswith("shm_ros"):
                return lambda: _ours(w, method, *(("upc",) if "UPC" in tool else ()))
            return lambda: _pyoma(w, method, list(tr.frequency_hz[:4]))

        # timing on the first window: the tools take turns, round after round, so that a change
        # of the machine's load falls on all of them; the median of the rounds is reported
        times: dict[str, list[tuple[float, float]]] = {t: [] for t in tools}
        results: dict[str, Any] = {}
        for _ in range(args.repeat):
            for tool in tools:
                out, wall, cpu = _once(call(tool, window, truth))
                results[tool] = out
                times[tool].append((wall, cpu))
        for tool in tools:
            f, z, phi = results[tool]
            acc = [_accuracy(truth, f, z, phi)]
            for w, tr in windows[1:]:
                acc.append(_accuracy(tr, *call(tool, w, tr)()))
            wall, cpu = np.median(np.array(times[tool]), axis=0)
            mem = _peak(call(tool, window, truth))
            rows.append({"tool": tool, "method": method, "time_s": float(wall), "cpu_s": float(cpu),
                         "wall_runs": [t[0] for t in times[tool]], "cpu_runs": [t[1] for t in times[tool]],
                         "peak_mib": mem, "accuracy_first": acc[0], "accuracy": _pool(acc),
                         "f_err_per_window": [[a.get("f_err_pct") for a in w] for w in acc]})
            print(f"{tool} {method}: median {wall:.3f} s wall, {cpu:.3f} s CPU over {args.repeat} "
                  f"rounds, {mem:.0f} MiB", flush=True)

    by_tool = {(x["tool"], x["method"]): x for x in rows}
    for x in rows:
        peer = by_tool[("pyOMA2 1.4.3", x["method"])]
        if x is not peer:
            x["f_err_minus_pyoma2"] = paired_frequency_difference(x["f_err_per_window"], peer["f_err_per_window"])

    camp_windows = [w for w, _ in windows[:8]]
    camps = []
    for method in methods if n_campaign > 0 else []:
        c = campaign(camp_windows, n_campaign, method)
        camps.append(c)
        print(f"campaign {method}: {c['windows']} windows in {c['wall_s']:.1f} s", flush=True)

    load = os.getloadavg()
    result = {"window": {"channels": N_CH, "samples": window.n_samples, "fs_hz": FS,
                         "block_rows": BLOCK_ROWS, "max_order": MAX_ORDER},
              "truth_hz": list(map(float, truth.frequency_hz[:4])),
              "truth_damping": list(map(float, truth.damping_ratio[:4])),
              "runs": rows, "campaign": camps, "load_average": load,
              "blas_threads": {k: os.environ.get(k) for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                                              "MKL_NUM_THREADS")},
              "accuracy_windows": len(windows),
              "date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime())}
    # a partial run (one method or no campaign) must not overwrite the full run's files
    full = len(methods) == 2 and n_campaign > 0
    stem = "bench_identify" if full else "bench_identify_" + "_".join(methods)
    (RESULTS / f"{stem}.json").write_text(json.dumps(result, indent=2))
    md = _markdown(result)
    (RESULTS / f"{stem}.md").write_text(md)
    print(md)
    return 0


def _markdown(r: dict) -> str:
    lines = ["| tool | method | wall (s) | CPU (s) | speed-up wall / CPU | peak traced memory (MiB) | "
             "mean freq. error % modes 1-4 | mean damping error % modes 1-4 | mean MAC modes 1-4 | "
             f"found (of {r['accuracy_windows']}) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    by = {(x["tool"], x["method"]): x for x in r["runs"]}
    for x in r["runs"]:
        ref = by[("pyOMA2 1.4.3", x["method"])]
        acc = x["accuracy"]

        def col(key, fmt, acc=acc):
            return " / ".join(fmt.format(a[key]) if a.get("found") else "miss" for a in acc)

        found = " / ".join(str(round(r["accuracy_windows"] * a.get("rate", 0.0))) for a in acc)
        lines.append(f"| {x['tool']} | {x['method']} | {x['time_s']:.3f} | {x['cpu_s']:.3f} | "
                     f"{ref['time_s'] / x['time_s']:.1f}x / {ref['cpu_s'] / x['cpu_s']:.1f}x | "
                     f"{x['peak_mib']:.0f} | {col('f_err_pct', '{:.2f}')} | "
                     f"{col('z_err_pct', '{:.1f}')} | {col('mac', '{:.3f}')} | {found} |")
    lines.append("")
    lines.append("Frequency error, ours minus pyOMA2's on the same windows (points of %, mean ± standard "
                 "error), modes 1-4:")
    for x in r["runs"]:
        if "f_err_minus_pyoma2" in x:
            lines.append(f"- {x['tool']} {x['method']}: " + "; ".join(
                f"{d['mean']:+.4f} ± {d['se']:.4f} ({'equal or smaller' if d['equal_or_smaller'] else 'LARGER'})"
                for d in x["f_err_minus_pyoma2"]))
    lines.append("")
    lines.append("| campaign | windows | workers | wall (s) | wall per window (s) | CPU per window (s) "
                 "| 1,152 windows, this machine (s) | 1,152 windows, CPU-s / 2 cores (s) |")
    lines.append("|---|---|---|---|---|---|---|---|")
    for c in r["campaign"]:
        lines.append(f"| {c['method']} | {c['windows']} | {c['workers']} | {c['wall_s']:.1f} | "
                     f"{c['per_window_s']:.3f} | {c['cpu_s'] / c['windows']:.3f} | "
                     f"{c['extrapolated_1152_s']:.0f} | {c['dedicated_2core_1152_s']:.0f} |")
    lines.append("")
    lines.append(f"Truth modes 1-4: {', '.join(f'{f:.3f}' for f in r['truth_hz'])} Hz; "
                 f"load average at the end (1/5/15 min) "
                 f"{' / '.join(f'{x:.1f}' for x in r['load_average'])}; wall and CPU are medians of "
                 "the timing rounds (tools in turn).")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
