"""Simulated earthquakes on an eight-story building with dampers, for the prediction tests and bench.

The records come from the simulator's building truth (``shm_ros.core.simulate``, scenario
``building-earthquake`` with the ``damper`` effect): scattered floor masses and story stiffnesses,
its own damping, sensor gain errors, offsets and noise, unmeasured wind. The analysis structure is
the nominal file with the damper braces declared (brace stiffness in the story stiffness, dashpots
as Kelvin-Voigt dampers), story heights, and story stiffnesses 10-20 % off: the lower and upper
halves each by a factor drawn from +-[10, 20] %, which the parameters ``k_lower``/``k_upper`` can
correct, while the truth's per-story scatter and damping stay a model-form error.
"""

from __future__ import annotations

import copy
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from shm_ros.core.simulate import named_scenario, simulate_campaign
from shm_ros.core.simulate.scenario import EffectRequest
from shm_ros.core.types import Window

FULL = os.environ.get("SHM_FULL", "") not in ("", "0")
STORY_HEIGHT_M = 3.5
K_REL, C_REL_S = 0.30, 0.02  # damper braces: k_d = K_REL k_story, c_d = C_REL_S k_d
DAMPER: dict[str, Any] = {"model": "kelvin_voigt", "k_rel": K_REL, "c_rel_s": C_REL_S}


@dataclass
class Quakes:
    structure: dict[str, Any]  # the analysis structure file (mapping)
    windows: list[Window]
    truth: dict[str, np.ndarray]  # per window id: (N, k) true signals of ``truth_names``
    truth_names: list[str]
    stiffness_error: tuple[float, float]


def simulate_quakes(seed: int, n_events: int = 6, *, duration_s: float = 60.0, fs: float = 50.0,
                    sensor_floors: tuple[int, ...] = (1, 4, 6, 8), truth_floors: tuple[int, ...] = (),
                    noise_rms_m_s2: float = 1e-3) -> Quakes:
    """``n_events`` windows with one earthquake each; ``truth_floors`` are simulated as hidden
    sensors ``h<k>``: their true absolute accelerations and (top story) drift are returned in
    ``truth`` but left out of the windows and the analysis structure."""
    camp, structure, err = quake_campaign(seed, n_events, duration_s=duration_s, fs=fs, sensor_floors=sensor_floors,
                                          truth_floors=truth_floors, noise_rms_m_s2=noise_rms_m_s2)
    keep = [s["id"] for s in structure["sensors"]]
    windows, truth = [], {}
    names = [f"h{k}" for k in truth_floors]
    for sw in camp.windows():
        w = sw.to_window()
        cols = [w.channel_names.index(s) for s in keep]
        w.channel_names, w.samples = keep, w.samples[:, cols]
        windows.append(w)
        if truth_floors:
            truth[w.window_id] = np.column_stack([sw.accel[:, sw.sensor_ids.index(n)] for n in names]
                                                 + [_true_drift(camp, sw, truth_floors)])
    return Quakes(structure, windows, truth, names + ["drift_top"], err)


def quake_campaign(seed: int, n_events: int = 6, *, duration_s: float = 60.0, fs: float = 50.0,
                   sensor_floors: tuple[int, ...] = (1, 4, 6, 8), truth_floors: tuple[int, ...] = (),
                   noise_rms_m_s2: float = 1e-3, effects: list[EffectRequest] | None = None,
                   **options: Any) -> tuple[Any, dict[str, Any], tuple[float, float]]:
    """The campaign of :func:`simulate_quakes` (``effects`` in addition to the damper braces,
    ``options``: scenario fields such as ``earthquakes``), its analysis structure and stiffness error."""
    sc = named_scenario("building-earthquake", n_windows=n_events, window_s=duration_s, fs=fs, seed=seed,
                        noise_rms_m_s2=noise_rms_m_s2, **options)
    sc.effects = [EffectRequest("damper", dict(DAMPER)), *(effects or [])]
    st = sc.structure
    st["sensors"] = ([{"id": "g0", "at": {"floor": 0}, "direction": "x"}]
                     + [{"id": f"f{k}", "at": {"floor": k}, "direction": "x"} for k in sensor_floors]
                     + [{"id": f"h{k}", "at": {"floor": k}, "direction": "x"} for k in truth_floors])
    camp = simulate_campaign(sc)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 77]))
    e = [float(rng.choice([-1.0, 1.0]) * rng.uniform(0.10, 0.20)) for _ in range(2)]
    err = (e[0], e[1])
    return camp, analysis_structure(st, err), err


def analysis_structure(simulated: dict[str, Any], err: tuple[float, float]) -> dict[str, Any]:
    """The nominal file as an engineer would write it for this building (see module doc)."""
    d = copy.deepcopy(simulated)
    floors = d["shear_building"]["floors"]
    n = len(floors)
    k_rel, c_rel = K_REL, C_REL_S
    for i, f in enumerate(floors):
        k = float(f["stiffness"])
        f["stiffness"] = k * (1 + k_rel) * (1 + err[0 if i < n // 2 else 1])
        f["height"] = STORY_HEIGHT_M
    d["shear_building"]["dampers"] = [{"between": [i, i + 1], "c": c_rel * k_rel * float(simulated[
        "shear_building"]["floors"][i]["stiffness"])} for i in range(n)]
    d["sensors"] = [s for s in d["sensors"] if not s["id"].startswith("h")]
    for p in d["parameters"]:
        p["prior"] = {"dist": "normal", "mean": 1.0, "std": 0.2}
    d["parameters"].append({"name": "zeta", "applies_to": "damping.ratios[*]",
                            "prior": {"dist": "lognormal", "mean": 1.0, "std": 0.5}})
    return d


def _true_drift(camp: Any, sw: Any, floors: tuple[int, ...]) -> np.ndarray:
    """Top-story drift (m) of the truth: its own linear system driven by the true ground motion
    (the window's ambient start and unmeasured wind left out), at the plan position of the top
    floor's hidden sensor (off the stiffness centre like every sensor: the drift there includes the
    story's twist). A story drift is the relative motion of two floors at one plan point: the floor
    below is read at the top sensor's plan position too, not at its own (misplaced) sensor, whose
    offset would add that floor's whole rotation times the two sensors' plan distance."""
    from dataclasses import replace

    n = max(floors)
    ids = list(sw.sensor_ids)
    tm = camp.truth_model
    top, below = ids.index(f"h{n}"), ids.index(f"h{n - 1}")
    xy = tm.info["sensor_xy_m"]
    saved = xy[below].copy()
    xy[below] = xy[top]
    try:
        sys, _ = tm.system(camp.factors(sw.index))
    finally:
        xy[below] = saved
    disp = replace(sys, C=sys.shapes, D=np.zeros_like(sys.D), participation=None, residue=None)
    u = np.zeros((sw.accel.shape[0], sys.B.shape[1]))
    u[:, 0] = sw.accel[:, ids.index("g0")]
    x = disp.simulate(u, 1.0 / sw.fs)
    rows = tm.signal_rows()  # x, y, z rows per sensor: the measured direction's
    return x[:, rows[top]] - x[:, rows[below]]
