"""Benchmark of merging roving setups: the laboratory steel frame against pyOMA2's PreGER.

Four setups of real data (test/data/pyoma_steel_frame: a roving 3-beam laser vibrometer at nodes 6, 7,
9, 10 and a fixed reference accelerometer, x and y, at node 24; 240 s at 256 Hz each; the laser's
velocities differentiated into accelerations, test/steel_frame_setups.py), decimated to 64 Hz, merged
offline from arrays three ways in the same run:

* ours, ``post``: each setup identified (SSI-cov, 60 block rows, orders up to 100, automatic picking),
  modes paired by the references' shapes and rescaled by least squares on the references;
* ours, ``pre``: one correlation Hankel matrix over all setups, rescaled to the first setup's
  references, identified once (same settings);
* pyOMA2 ``MultiSetup_PreGER`` + ``SSI_MS`` (covariance, 60 block rows, order 100); its modes are
  its own stable poles (label 1) grouped within 1 %, the four lowest groups present at >= 20 orders,
  each extracted (``mpe``) at the lowest order where it is stable.

Compared for the peer's 4 modes: our nearest mode's frequency (within 1 %) and the MAC (>= 0.9) over
all 14 channels, and for information over the 12 roving channels alone (the glued part). Writes
bench/results/bench_roving.{json,md}; ``--write-reference`` also stores the peer's result in
test/data/pyoma_steel_frame/pyoma2_preger.json, which the CI test compares against.

    python -m bench.bench_roving [--write-reference]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))

import steel_frame_setups as sf  # noqa: E402

from shm_ros.core.modal import mac, real_shape  # noqa: E402

RESULTS = ROOT / "bench" / "results"


def peer() -> tuple[np.ndarray, np.ndarray, float]:
    """pyOMA2 PreGER: frequencies (4,), real shapes (4, 14) in sf.channel_keys() order, seconds."""
    import logging

    from pyoma2.algorithms import SSI_MS
    from pyoma2.setup import MultiSetup_PreGER

    logging.disable(logging.INFO)
    data, _ = sf.raw_setups()
    # pyOMA2's order per setup: references first, then the roving channels (ref_ind = columns 3, 4)
    t0 = time.perf_counter()
    msp = MultiSetup_PreGER(fs=sf.FS, ref_ind=[[3, 4]] * len(data), datasets=[d - d.mean(axis=0) for d in data])
    msp.decimate_data(q=int(sf.FS / sf.RATE))
    alg = SSI_MS(name="ssi", method="cov", br=sf.CONFIG.block_rows, ordmax=sf.CONFIG.max_order)
    msp.add_algorithms(alg)
    msp.run_all()
    sel, orders = peer_selection(np.asarray(alg.result.Fn_poles), np.asarray(alg.result.Lab))
    msp.mpe("ssi", sel_freq=sel, order_in=orders)
    seconds = time.perf_counter() - t0
    r = alg.result
    phi = np.asarray(r.Phi)
    shapes = np.array([real_shape(phi[:, k]) for k in range(phi.shape[1])])
    return np.asarray(r.Fn, float), shapes, seconds


def peer_selection(fn: np.ndarray, lab: np.ndarray, n_modes: int = 4, min_orders: int = 20
                   ) -> tuple[list[float], list[int]]:
    """The peer's own pick: its stable poles (label 1) grouped by frequency (1 %), the lowest
    ``n_modes`` groups present at >= ``min_orders`` orders; each at its median frequency and picked
    at the lowest order where it is stable."""
    f = np.where(lab == 1, fn, np.nan)
    sel: list[float] = []
    orders: list[int] = []
    for x in np.sort(f[np.isfinite(f)]):
        if any(abs(x / s - 1) < 0.01 for s in sel) or len(sel) == n_modes:
            continue
        near = np.abs(f - x) < 0.01 * x
        cols = np.flatnonzero(near.any(axis=0))
        if cols.size >= min_orders:
            centre = float(np.median(f[near]))
            sel.append(centre)
            orders.append(int(np.flatnonzero((np.abs(f - centre) < 0.01 * centre).any(axis=0))[0]))
    return sel, orders


def compare(freqs, shapes, keys, modes) -> list[dict]:
    """Per peer mode: our nearest mode's frequency, the MAC over all channels and over the roving ones."""
    rows = []
    roving = np.array([k not in sf.REFS for k in keys])
    for f, s in zip(freqs, shapes, strict=True):
        ff = np.array([m.frequency_hz for m in modes])
        j = int(np.argmin(np.abs(ff - f)))
        v = modes[j].vector(keys)
        rows.append({"peer_hz": float(f), "ours_hz": float(ff[j]), "diff_pct": float(100 * (ff[j] / f - 1)),
                     "mac": float(mac(v, s)), "mac_roving": float(mac(v[roving], s[roving]))})
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--write-reference", action="store_true")
    args = ap.parse_args(argv)
    keys = sf.channel_keys()
    f_peer, phi_peer, t_peer = peer()
    out: dict = {"peer": {"frequency_hz": f_peer.tolist(), "shapes": phi_peer.tolist(), "channels": keys,
                          "seconds": t_peer, "tool": "pyoma-2==1.4.3 MultiSetup_PreGER + SSI_MS(cov)"}}
    ok = True
    for method in ("post", "pre"):
        t0 = time.perf_counter()
        modes = sf.ours(method)
        out[method] = {"seconds": time.perf_counter() - t0, "modes": compare(f_peer, phi_peer, keys, modes)}
        ok &= all(abs(r["diff_pct"]) < 1 and r["mac"] >= 0.9 for r in out[method]["modes"])
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "bench_roving.json").write_text(json.dumps(out, indent=1))
    lines = ["| mode | pyOMA2 PreGER Hz | post Hz | post diff % | post MAC (roving only) | pre Hz | pre diff % "
             "| pre MAC (roving only) |", "|---|---|---|---|---|---|---|---|"]
    for k in range(len(f_peer)):
        a, b = out["post"]["modes"][k], out["pre"]["modes"][k]
        lines.append(f"| {k + 1} | {f_peer[k]:.4f} | {a['ours_hz']:.4f} | {a['diff_pct']:+.3f} | {a['mac']:.4f} "
                     f"({a['mac_roving']:.4f}) | {b['ours_hz']:.4f} | {b['diff_pct']:+.3f} | {b['mac']:.4f} "
                     f"({b['mac_roving']:.4f}) |")
    lines.append(f"\nseconds: pyOMA2 {t_peer:.1f}, post {out['post']['seconds']:.1f}, pre {out['pre']['seconds']:.1f}")
    (RESULTS / "bench_roving.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    if args.write_reference:
        ref = {"source": "bench/bench_roving.py --write-reference", **out["peer"]}
        ref.pop("seconds")
        (sf.DATA / "pyoma2_preger.json").write_text(json.dumps(ref, indent=1) + "\n")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
