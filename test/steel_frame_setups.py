"""The laboratory steel frame's four setups (test/data/pyoma_steel_frame) as roving-sensor setups,
and this project's two merges of them (used by test/test_roving_steel_frame.py and
bench/bench_roving.py).

Setups 2-5: the laser vibrometer (three beams, channels 0-2) roves over nodes 6, 7, 9 and 10; the
reference accelerometer at node 24 (x, y: channels 3, 4) stays. Roving channels are named
``n<node>_<beam>`` (``n6_l``...). Decimated from 256 Hz to 64 Hz by the project's pre-processing."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from shm_ros.core.identify import IdentifyConfig
from shm_ros.core.preprocess import PreprocessConfig
from shm_ros.core.roving.merge_post import GlobalMode
from shm_ros.core.roving.offline import merge_arrays

DATA = Path(__file__).resolve().parent / "data" / "pyoma_steel_frame"
NODES = {2: 6, 3: 7, 4: 9, 5: 10}
BEAMS = ("l", "r", "t")
REFS = ["ref_x", "ref_y"]
FS = 256.0
RATE = 64.0
CONFIG = IdentifyConfig(method="ssi-cov", block_rows=60, max_order=100, uncertainty=False, band="off",
                        reference_channels=REFS)


def derivative(v: np.ndarray, fs: float) -> np.ndarray:
    """Time derivative of (n, c) records by FFT (exact for the band, no gain error near the modes)."""
    v = v - v.mean(axis=0)
    f = np.fft.rfftfreq(v.shape[0], 1.0 / fs)
    return np.fft.irfft(np.fft.rfft(v, axis=0) * (2j * np.pi * f)[:, None], n=v.shape[0], axis=0)


def raw_setups() -> tuple[list[np.ndarray], list[list[str]]]:
    """The four records (61,440 x 5, 256 Hz) with the laser's velocities turned into accelerations
    (velocity leads acceleration by 90 degrees: mixed as they are, the roving components of a mode
    would be imaginary against the references' and vanish from a real shape), and their names."""
    data, names = [], []
    for setup, node in NODES.items():
        x = np.load(DATA / f"measurement_{setup}.npy").astype(np.float64)
        x[:, :3] = derivative(x[:, :3], FS)
        data.append(x)
        names.append([f"n{node}_{b}" for b in BEAMS] + REFS)
    return data, names


def channel_keys() -> list[str]:
    """The merged shape's channels in the peer's order: references, then each setup's roving ones."""
    return REFS + [f"n{node}_{b}" for node in NODES.values() for b in BEAMS]


def ours(method: str) -> list[GlobalMode]:
    """Global modes of the four setups merged after (``post``) or before (``pre``) identification."""
    data, names = raw_setups()
    modes, _ = merge_arrays(data, names, REFS, FS, CONFIG, method, PreprocessConfig(target_rate_hz=RATE))
    return modes

