"""Input-output identification beside a peer: shm_ros's ``ssi-io`` and ``mdof`` (SRIM, OKID-ERA).

Two kinds of data, the same channels for every tool:

* simulated: scenario ``building-earthquake`` (``shm_ros.core.simulate``): the eight-story building
  on a fixed base, one earthquake per 300 s window at 100 Hz, input ``g0`` (ground), outputs floors
  1, 4, 6, 8. Truth: the simulator's own in-plane (x) modes 1-4 (its model, not the analysis model). Accuracy:
  each true mode paired with the nearest identified frequency within 5 %.
* real: the CSMIP V2 record in ``test/data/csmip_v2_sample`` (Capistrano Beach I5/Via California
  bridge, Inglewood earthquake of 2009): inputs the two free-field horizontals (channels 2 and 3),
  outputs the six horizontal deck channels (6, 7, 8, 10, 11, 12). No truth: the modes found by both
  (mutual nearest with MAC >= 0.9) are listed side by side.

Settings: shm_ros = ``identify`` defaults (``auto`` -> ``ssi-io``; band, decimation and block rows
chosen automatically, orders up to 60) on the simulated windows, with the band from the nominal
model of the scenario's structure file as ``shm-ros identify`` takes it, and on the bridge's 200 Hz record
(no nominal model: the band comes from the spectrum); mdof = the bridge decimated to 50 Hz, one
model of order
``--order`` (default 20) and horizon ``--horizon`` (default 40), ``find="AC"`` (modes depend on
A and C only). Timed: CPU seconds of the calling process with one BLAS thread (best of
``--repeat``); mdof's ``find="ABCD"`` would add an output-error step run in worker processes.

    python -m bench.bench_peers_io              # 10 simulated windows (OKID-ERA on 1) + the bridge
    python -m bench.bench_peers_io --windows 3  # quicker
    python -m bench.bench_peers_io --okid-windows 0 --no-bridge --identify '{"max_order": 60}'
        # shm_ros with other identify options (JSON of IdentifyConfig fields)
    python -m bench.bench_peers_io --first-seed 10 --windows 30 --okid-windows 0 --no-bridge

Accuracy: mean frequency and damping errors and mean MAC of the shapes at the four outputs with the
simulator's own shapes, per true mode.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from functools import partial
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import scipy.signal as sig  # noqa: E402

from shm_ros.core.band import band_frequencies  # noqa: E402
from shm_ros.core.identify import IdentifyConfig, identify_prepared, identify_window  # noqa: E402
from shm_ros.core.modal import mac_matrix  # noqa: E402
from shm_ros.core.preprocess import preprocess  # noqa: E402
from shm_ros.core.simulate.campaign import simulate_campaign  # noqa: E402
from shm_ros.core.simulate.scenario import named_scenario  # noqa: E402
from shm_ros.core.structure import structure_from_dict  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results"
V2_ZIP = ROOT / "test" / "data" / "csmip_v2_sample" / "Inglewood_17May2009_CE13795P.zip"
BRIDGE_INPUTS = [2, 3]  # free field, 270 and 360 degrees
BRIDGE_OUTPUTS = [6, 7, 8, 10, 11, 12]  # deck: transverse and longitudinal
N_MODES = 4


def _cpu(fn, repeat: int):
    best, out = np.inf, None
    for _ in range(repeat):
        c0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - c0)
    return out, best


def mdof_modes(u: np.ndarray, y: np.ndarray, dt: float, method: str, order: int, horizon: int):
    """Frequencies, damping ratios and complex shapes (rows) of an mdof realization; inputs and
    outputs as (samples, channels)."""
    import mdof

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        real = mdof.system(u.T, y.T, dt=dt, method=method, order=order, horizon=horizon, find="AC")
        modes = list(real.modes().values())
    f = np.array([m["freq"] for m in modes], float)
    z = np.array([m["damp"] for m in modes], float)
    phi = np.array([np.asarray(m["modeshape"], complex) for m in modes]).reshape(len(modes), -1)
    k = np.argsort(f)
    return f[k], z[k], phi[k]


def bridge_record() -> tuple[np.ndarray, np.ndarray, float]:
    """Free-field inputs and deck outputs of the CSMIP record, (samples, channels), 50 Hz."""
    from shm_ros.io.importers import read_v2

    rec = read_v2(V2_ZIP)[0]
    x = sig.decimate(rec.samples, 4, axis=0, zero_phase=True)
    return x[:, [c - 1 for c in BRIDGE_INPUTS]], x[:, [c - 1 for c in BRIDGE_OUTPUTS]], rec.sample_rate_hz / 4


def shm_default_bridge_modes(config: IdentifyConfig | None = None):
    """shm_ros's default identification of the bridge: the recorded 200 Hz channels, the
    free-field pair as inputs, band, decimation and block rows chosen automatically. Frequencies,
    damping ratios, complex shapes (rows, deck channels in ``BRIDGE_OUTPUTS`` order) and the band."""
    from shm_ros.io.importers import read_v2

    rec = read_v2(V2_ZIP)[0]
    chans = BRIDGE_INPUTS + BRIDGE_OUTPUTS
    names = [rec.channel_names[c - 1] for c in chans]
    prep = preprocess(rec.samples[:, [c - 1 for c in chans]], rec.sample_rate_hz, names)
    res = identify_prepared(prep, config or IdentifyConfig(), names[:len(BRIDGE_INPUTS)])
    assert res.estimate.method == "ssi-io" and res.channel_names == names[len(BRIDGE_INPUTS):]
    picked = res.diagram.picked
    return (np.array([p.frequency_hz for p in picked]), np.array([p.damping_ratio for p in picked]),
            np.array([p.mode_shape_complex for p in picked]).reshape(len(picked), len(BRIDGE_OUTPUTS)),
            res.band)


def mutual_modes(f1, phi1, f2, phi2, mac_min: float = 0.9) -> list[tuple[int, int, float]]:
    """Pairs (i, j, MAC) of mutually nearest modes: j is the mode of the second set nearest to i
    in frequency among those with MAC >= ``mac_min``, and i the one of the first set nearest to j
    among those alike j (so no mode pairs twice)."""
    if len(f1) == 0 or len(f2) == 0:
        return []
    f1, f2 = np.asarray(f1, float), np.asarray(f2, float)
    mac = mac_matrix(phi1, phi2)
    alike = mac >= mac_min

    def nearest(fa: np.ndarray, fb: np.ndarray, ok: np.ndarray) -> np.ndarray:
        dist = np.where(ok, np.abs(fa[:, None] - fb[None, :]), np.inf)
        return np.where(ok.any(axis=1), np.argmin(dist, axis=1), -1)

    to2, to1 = nearest(f1, f2, alike), nearest(f2, f1, alike.T)
    return [(i, int(j), float(mac[i, j])) for i, j in enumerate(to2) if j >= 0 and to1[j] == i]


def _errors(f, z, ft, zt, phi=None, phit=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frequency and damping errors of the identified mode nearest each true one (within 5 %),
    and the MAC of its shape with the true shape (rows of ``phi`` and ``phit``; NaN without)."""
    ef, ez, mac = np.full(N_MODES, np.nan), np.full(N_MODES, np.nan), np.full(N_MODES, np.nan)
    for k in range(N_MODES):
        if len(f) == 0:
            continue
        j = int(np.argmin(np.abs(f - ft[k])))
        if abs(f[j] / ft[k] - 1) <= 0.05:
            ef[k], ez[k] = abs(f[j] / ft[k] - 1), abs(z[j] - zt[k])
            if phi is not None and phit is not None:
                mac[k] = mac_matrix(phi[j][None], phit[k][None])[0, 0]
    return ef, ez, mac


def simulated(n_windows: int, order: int, horizon: int, repeat: int, okid_windows: int,
              identify: dict | None = None, first_seed: int = 0) -> list[dict]:
    rows: dict[str, dict] = {}
    for seed in range(first_seed, first_seed + n_windows):
        sc = named_scenario("building-earthquake", n_windows=1, window_s=300.0, seed=seed)
        campaign = simulate_campaign(sc)
        sim = campaign.window(0)
        w = sim.to_window()
        # what `shm-ros identify` does with the structure file: its nominal model sets the band
        spec = structure_from_dict(campaign.nominal_structure)
        nominal, _ = band_frequencies(spec, "auto", IdentifyConfig().band_modes)
        # the in-plane (x) modes the ground input excites; y and twist modes are in the truth too
        in_x = np.asarray(sim.truth["mode_families"]) == "x"
        ft = np.asarray(sim.truth["frequencies_hz"])[in_x][:N_MODES]
        zt = np.asarray(sim.truth["damping_ratios"])[in_x][:N_MODES]
        shapes = sim.truth["mode_shapes"]  # sensor -> value per mode
        assert w.input_channel is not None  # the building declares its ground sensor as input
        k_in = w.channel_names.index(w.input_channel)
        u = w.samples[:, [k_in]] - w.samples[:, [k_in]].mean(axis=0)
        y = np.delete(w.samples, k_in, axis=1)
        outputs = [c for c in w.channel_names if c != w.input_channel]
        phit = np.array([[shapes[c][k] for c in outputs] for k in np.flatnonzero(in_x)[:N_MODES]])
        y = y - y.mean(axis=0)
        dt = 1.0 / w.sample_rate_hz
        tools = {
            "shm_ros ssi-io (identify defaults)" if not identify else
            f"shm_ros ssi-io ({json.dumps(identify)})": partial(_ours, w, nominal, outputs, identify or {}),
            f"mdof SRIM (order {order})": partial(mdof_modes, u, y, dt, "srim", order, horizon),
        }
        if seed - first_seed < okid_windows:  # minutes of CPU per 300 s window
            tools[f"mdof OKID-ERA (order {order})"] = partial(mdof_modes, u, y, dt, "okid-era", order, horizon)
        for name, fn in tools.items():
            (f, z, phi), cpu = _cpu(fn, repeat if seed == first_seed and "OKID" not in name else 1)
            ef, ez, mac = _errors(f, z, ft, zt, phi, phit)
            r = rows.setdefault(name, {"tool": name, "ef": [], "ez": [], "mac": [], "cpu": []})
            r["ef"].append(ef)
            r["ez"].append(ez)
            r["mac"].append(mac)
            r["cpu"].append(cpu)
        print(f"window {seed}: done", flush=True)
    out = []
    for r in rows.values():
        ef, ez, mac = np.array(r["ef"]), np.array(r["ez"]), np.array(r["mac"])
        found = np.isfinite(ef)
        out.append({"tool": r["tool"], "windows": len(r["ef"]), "found": found.sum(0).tolist(),
                    "mean_f_err_pct": [float(100 * np.nanmean(ef[:, k])) if found[:, k].any() else None
                                       for k in range(N_MODES)],
                    "mean_z_err_points": [float(100 * np.nanmean(ez[:, k])) if found[:, k].any() else None
                                          for k in range(N_MODES)],
                    "mean_mac_truth": [float(np.nanmean(mac[:, k])) if found[:, k].any() else None
                                       for k in range(N_MODES)],
                    "cpu_s_first_window": float(r["cpu"][0]), "cpu_s_median": float(np.median(r["cpu"]))})
    return out


def _ours(window, nominal: list[float] | None, outputs: list[str], options: dict):
    """Frequencies, damping ratios and shapes (rows, ``outputs`` order) of shm_ros's identify
    with the structure's band (``options``: IdentifyConfig fields given on the command line)."""
    est = identify_window(window, IdentifyConfig.from_dict({"nominal_frequencies_hz": nominal, **options}))
    cols = [est.sensor_ids.index(c) for c in outputs]
    return (np.array([m.frequency_hz for m in est.modes]), np.array([m.damping_ratio for m in est.modes]),
            np.array([np.asarray(m.mode_shape, float)[cols] for m in est.modes]).reshape(len(est.modes), -1))


def bridge(order: int, horizon: int, repeat: int) -> dict:
    u, y, fs = bridge_record()
    (f1, z1, p1, band), c1 = _cpu(shm_default_bridge_modes, repeat)
    (f2, z2, p2), c2 = _cpu(lambda: mdof_modes(u, y, 1 / fs, "srim", order, horizon), repeat)
    (f3, z3, _), c3 = _cpu(lambda: mdof_modes(u, y, 1 / fs, "okid-era", order, horizon), 1)
    pairs = mutual_modes(f1, p1, f2, p2)
    return {"fs_hz": fs, "samples": int(y.shape[0]), "shm_ros_band": band.describe(),
            "shm_ros_hz": f1.tolist(), "shm_ros_damping": z1.tolist(),
            "srim_hz": f2[f2 < 0.45 * fs].tolist(), "srim_damping": z2[f2 < 0.45 * fs].tolist(),
            "okid_era_hz": f3[f3 < 0.45 * fs].tolist(),
            "pairs": [{"shm_ros_hz": float(f1[i]), "srim_hz": float(f2[j]), "mac": m,
                       "diff_pct": float(100 * (f1[i] / f2[j] - 1)),
                       "shm_ros_damping": float(z1[i]), "srim_damping": float(z2[j])} for i, j, m in pairs],
            "cpu_s": {"shm_ros ssi-io": c1, "mdof SRIM": c2, "mdof OKID-ERA": c3}}


def _markdown(sim: list[dict], br: dict | None) -> str:
    lines = ["| tool | windows | found modes 1-4 | mean freq. error % modes 1-4 | mean damping error "
             "(points) modes 1-4 | mean MAC to the true shapes modes 1-4 | CPU s (first window, best of "
             "repeats) | CPU s median |",
             "|---|---|---|---|---|---|---|---|"]

    def fmt(v, f):
        return " / ".join("miss" if x is None else f.format(x) for x in v)

    for r in sim:
        lines.append(f"| {r['tool']} | {r['windows']} | {' / '.join(map(str, r['found']))} | "
                     f"{fmt(r['mean_f_err_pct'], '{:.3f}')} | {fmt(r['mean_z_err_points'], '{:.2f}')} | "
                     f"{fmt(r['mean_mac_truth'], '{:.4f}')} | "
                     f"{r['cpu_s_first_window']:.3f} | {r['cpu_s_median']:.3f} |")
    if br is None:
        return "\n".join(lines) + "\n"
    lines += ["", f"Bridge record ({br['samples']} samples at {br['fs_hz']:.0f} Hz for mdof): shm_ros "
              f"({br['shm_ros_band']}) picked "
              f"{', '.join(f'{f:.3f}' for f in br['shm_ros_hz'])} Hz; SRIM's poles below 0.45 fs "
              f"{', '.join(f'{f:.3f}' for f in br['srim_hz'])} Hz; OKID-ERA's "
              f"{', '.join(f'{f:.3f}' for f in br['okid_era_hz']) or 'none'} Hz. CPU s: "
              + ", ".join(f"{k} {v:.3f}" for k, v in br["cpu_s"].items()) + ".", "",
              "| shm_ros ssi-io (Hz) | mdof SRIM (Hz) | difference % | MAC | damping shm_ros / SRIM |",
              "|---|---|---|---|---|"]
    for p in br["pairs"]:
        lines.append(f"| {p['shm_ros_hz']:.3f} | {p['srim_hz']:.3f} | {p['diff_pct']:+.2f} | {p['mac']:.3f} | "
                     f"{p['shm_ros_damping']:.3f} / {p['srim_damping']:.3f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--windows", type=int, default=10, help="simulated windows (seeds 0..N-1)")
    ap.add_argument("--order", type=int, default=20, help="mdof model order")
    ap.add_argument("--horizon", type=int, default=40, help="mdof horizon (block rows)")
    ap.add_argument("--repeat", type=int, default=3, help="timing repeats on the first window")
    ap.add_argument("--okid-windows", type=int, default=1,
                    help="simulated windows also given to OKID-ERA (slow: minutes of CPU each)")
    ap.add_argument("--first-seed", type=int, default=0, help="first simulated window's seed")
    ap.add_argument("--identify", type=json.loads, default=None, metavar="JSON",
                    help='shm_ros identify options instead of the defaults, e.g. \'{"max_order": 60}\'')
    ap.add_argument("--no-bridge", action="store_true", help="leave the bridge record out")
    args = ap.parse_args(argv)
    try:
        import mdof  # noqa: F401
    except ImportError:
        print("mdof is not installed (requirements/bench.txt)", file=sys.stderr)
        return 1
    sim = simulated(args.windows, args.order, args.horizon, args.repeat, args.okid_windows, args.identify,
                    args.first_seed)
    br = None if args.no_bridge else bridge(args.order, args.horizon, args.repeat)
    RESULTS.mkdir(parents=True, exist_ok=True)
    result = {"simulated": sim, "bridge": br, "load_average": os.getloadavg()[0],
              "date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime())}
    (RESULTS / "bench_peers_io.json").write_text(json.dumps(result, indent=2))
    md = _markdown(sim, br)
    (RESULTS / "bench_peers_io.md").write_text(md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
