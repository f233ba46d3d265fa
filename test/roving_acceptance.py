"""The girder-roving acceptance run, shared by test/test_roving_acceptance.py (reduced size) and the
full-size command (``SHM_FULL=1``): simulate, cut, merge, compare with the truth without the robot."""

from __future__ import annotations

import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from shm_ros.core.modal import mac
from shm_ros.core.roving.pipeline import RovingConfig, RovingResult, roving_modes
from shm_ros.core.roving.transforms import TransformBuffer
from shm_ros.core.simulate.roving import RovingOptions, RovingRecording, simulate_roving
from shm_ros.io.structure import load_structure

ROOT = Path(__file__).resolve().parents[1]
SPEC = load_structure(ROOT / "examples" / "girder_roving.yaml")


def acceptance_seeds(n: int = 10) -> list[int]:
    """Full-size seeds drawn from the git tree of ``shm_ros/core/roving`` (no seed shopping: a change
    to the pipeline draws new ones), from 1,000 up, disjoint from the development seeds (0-999)."""
    tree = subprocess.run(["git", "rev-parse", "HEAD:shm_ros/core/roving"], cwd=ROOT, capture_output=True,
                          text=True, check=True).stdout.strip()
    rng = np.random.default_rng(int(tree[:12], 16))
    return [int(s) for s in rng.choice(np.arange(1000, 1_000_000), n, replace=False)]


@dataclass
class Outcome:
    rec: RovingRecording
    res: RovingResult
    freq_err_pct: list[float]  # vertical modes 1-3
    macs: list[float]
    coverage: list[float]  # fraction of the visited points and references each mode covers


def buffer_of(rec: RovingRecording) -> TransformBuffer:
    buf = TransformBuffer(cache_s=None)
    for s in rec.tf + rec.tf_static:
        buf.set_transform(s.parent, s.child, s.stamp_ns, s.translation, s.rotation, static=s in rec.tf_static)
    return buf


def run(seed: int, dwell_s: float, n_points: int, merge: str = "post", fs: float = 100.0) -> Outcome:
    rec = simulate_roving(SPEC, RovingOptions(seed=seed, dwell_s=dwell_s, n_points=n_points, fs=fs))
    res = roving_modes(SPEC, rec.times_ns, fs, rec.references, rec.roving, buffer_of(rec), RovingConfig(merge=merge))
    visited = list(rec.references) + [p for kind, _, _, p in rec.phases if kind == "dwell"]
    keys = rec.truth.sensor_ids
    vertical = [j for j, f in enumerate(rec.truth.families) if f == "vertical"][:3]
    f = np.array([g.frequency_hz for g in res.global_modes])
    errs, macs, cover = [], [], []
    for j in vertical:
        ft = rec.truth.frequencies_hz[j]
        k = int(np.argmin(np.abs(f - ft))) if f.size else -1
        if k < 0:
            errs.append(np.inf), macs.append(0.0), cover.append(0.0)
            continue
        g = res.global_modes[k]
        have = [p for p in visited if p in g.shape and np.isfinite(g.shape[p])]
        errs.append(float(100 * (f[k] / ft - 1)))
        macs.append(float(mac(g.vector(have), rec.truth.shapes[[keys.index(p) for p in have], j])))
        cover.append(len(have) / len(visited))
    return Outcome(rec, res, errs, macs, cover)


if __name__ == "__main__":  # per-seed figures: python test/roving_acceptance.py [full] (docs/roving.md)
    import sys

    full = sys.argv[1:2] == ["full"]
    size = dict(dwell_s=120.0, n_points=12, fs=100.0) if full else dict(dwell_s=60.0, n_points=10, fs=50.0)
    seeds = [int(a) for a in sys.argv[2:]] or (acceptance_seeds() if full else list(range(3)))
    for seed in seeds:
        out = run(seed, **size)
        print(f"| {seed} | {', '.join(f'{e:+.2f}' for e in out.freq_err_pct)} | "
              f"{', '.join(f'{m:.4f}' for m in out.macs)} | {', '.join(f'{c:.2f}' for c in out.coverage)} | "
              f"{1e3 * out.res.clock_offset_s:.2f} ms |", flush=True)
