"""Tracked-modes tables of a 3-story shear building from the analysis model itself (the model's truth).

The table's frequencies are the nominal model's at parameters off their nominal values (so the baseline
calibration has work to do), optionally with a stiffness that follows the temperature on every story
(a vocabulary effect: ``temperature_dependent_stiffness``), optionally with one mode's frequency
moved by a factor that no parameter group produces alone (model-form error the class cannot absorb),
with 0.3 % identification scatter per window and mode. Windows every 2 h over 20 days, an air
temperature with a daily and a slow course.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from shm_ros.core.models import build_model
from shm_ros.core.simulate.scenario import shear_building_structure
from shm_ros.core.structure import structure_from_dict

SCATTER = 0.003
THETA_TRUE = (1.03, 0.96)  # k_lower, k_upper of the truth


def building_table(out: Path, seed: int, n_windows: int = 240, slope_per_c: float = 0.0,
                   mode_off: tuple[int, float] | None = None) -> tuple[Path, Path]:
    """Writes ``out/structure.yaml`` and ``out/modes.csv``; returns their paths. ``slope_per_c``: the
    stiffness of every story changes by this fraction per degC from 10 degC; ``mode_off`` (k, factor):
    mode k (1-based) of the truth multiplied by ``factor``."""
    out.mkdir(parents=True, exist_ok=True)
    doc = shear_building_structure(3)
    spec = structure_from_dict(doc)
    model = build_model(spec)
    rng = np.random.default_rng([8100, seed])
    t_s = np.arange(n_windows) * 7200.0
    temp = 10.0 + 6.0 * np.sin(2 * np.pi * t_s / 86400.0) + 4.0 * np.sin(2 * np.pi * t_s / (18 * 86400.0))
    temp += 0.3 * rng.standard_normal(n_windows)
    f0 = model.modes(np.array(THETA_TRUE), 3).frequencies_hz
    factor = np.maximum(1.0 + slope_per_c * (temp - 10.0), 0.2)
    f = np.sqrt(factor)[:, None] * f0[None]  # every story alike: every frequency by the square root
    if mode_off is not None:
        f[:, mode_off[0] - 1] *= mode_off[1]
    f *= 1.0 + SCATTER * rng.standard_normal(f.shape)
    times = [np.datetime_as_string(np.datetime64("2024-05-01T00:00:00") + np.timedelta64(int(s), "s")) + "Z"
             for s in t_s]
    rows = ["time," + ",".join(f"mode{k + 1}_hz" for k in range(3)) + ",temperature_c"]
    rows += [f"{ti}," + ",".join(f"{x:.6f}" for x in fi) + f",{te:.3f}"
             for ti, fi, te in zip(times, f, temp, strict=True)]
    (out / "modes.csv").write_text("\n".join(rows) + "\n")
    (out / "structure.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return out / "structure.yaml", out / "modes.csv"


def null_campaign(seed: int, kind: str, n_windows: int):
    """A null replicate for ``bench/calibrate_explain.py --generator explain_fit_synth:null_campaign``:
    the building's own truth without an effect, (ModalObservations, StructureSpec). ``kind`` is
    ignored (one kind here)."""
    import tempfile

    from shm_ros.io.structure import load_structure
    from shm_ros.io.tables import read_tracked_modes

    with tempfile.TemporaryDirectory() as tmp:
        structure, table = building_table(Path(tmp), seed, n_windows=n_windows)
        return read_tracked_modes(table), load_structure(structure)
