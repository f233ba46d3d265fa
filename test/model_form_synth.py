"""Modal tables whose truth lies outside the analysis model's class (for the model-error tests).

The truth is the simulator's campaign truth of the ``girder`` scenario (finer mesh, scattered
properties, misplaced sensors) with rotationally restrained bearings, which the analysis model
(the nominal girder, pinned bearings, parameters E_scale and bearing_scale) cannot represent, and a
deck stiffness that follows the air temperature (the campaign's daily cycle and slow drift). Per
window the true frequencies come from the truth model's eigen-solution at the window's temperature
factor, without synthesising signals; identification scatter (0.2-0.5 % per mode) and shape noise
(2 % of the unit-max shape) are drawn independently for every window.
"""

from __future__ import annotations

import copy

import numpy as np

from shm_ros.core.models import build_model
from shm_ros.core.observations import ModalObservations
from shm_ros.core.simulate.campaign import simulate_campaign
from shm_ros.core.simulate.scenario import GIRDER_STRUCTURE, EffectRequest, named_scenario
from shm_ros.core.structure import structure_from_dict

FREQ_SCATTER = (0.002, 0.003, 0.004, 0.005)
SHAPE_NOISE = 0.02
N_MODES = 4


def analysis_model():
    spec = structure_from_dict(copy.deepcopy(GIRDER_STRUCTURE))
    return spec, build_model(spec)


def _vertical(modal) -> np.ndarray:
    """Indices of the in-plane (vertical) truth modes: by the per-mode family mark when the truth
    has one, else all (the girder truth is then vertical only)."""
    for name in ("families", "family", "mode_families"):
        fam = getattr(modal, name, None)
        if fam is not None and len(fam) == len(modal.frequencies_hz):
            return np.array([i for i, f in enumerate(fam) if str(f) == "vertical"], dtype=int)
    return np.arange(len(modal.frequencies_hz))


def model_form_table(seed: int, n_windows: int, rng: np.random.Generator | None = None) -> ModalObservations:
    """``n_windows`` 10-minute windows (time order) of the first four vertical modes."""
    structure = copy.deepcopy(GIRDER_STRUCTURE)
    for b in structure["girder"]["bearings"]:
        b["k_rotation"] = 2.0e9  # the model's bearings are pinned: outside its class
    sc = named_scenario("girder", n_windows=n_windows, window_s=600.0, pause_s=2.0, seed=seed,
                        structure=structure)
    sc.effects = [EffectRequest("temperature_linear", {})]
    camp = simulate_campaign(sc)
    tm = camp.truth_model
    factors = [camp.factors(i) for i in range(n_windows)]
    keys = sorted({k for f in factors for k in f})
    sensors = [s["id"] for s in GIRDER_STRUCTURE["sensors"]]
    rows = [tm.sensor_ids.index(s) for s in sensors]
    if len(keys) != 1:
        raise AssertionError(f"expected one temperature effect group, got {keys}")
    key = keys[0]
    values = np.array([f[key] for f in factors])
    grid = np.linspace(values.min(), values.max(), 7) if np.ptp(values) > 0 else values[:1]
    freqs = []
    shapes = None
    for g in grid:
        _, modal = tm.system({key: float(g)})
        idx = _vertical(modal)[:N_MODES]
        freqs.append(np.asarray(modal.frequencies_hz)[idx])
        if shapes is None:
            shapes = np.asarray(modal.shapes)[rows][:, idx].T  # (modes, sensors), unit max
    freqs_a = np.array(freqs)
    f_true = (np.column_stack([np.interp(values, grid, freqs_a[:, k]) for k in range(N_MODES)])
              if grid.size > 1 else np.repeat(freqs_a, n_windows, axis=0))
    rng = rng or np.random.default_rng(10_000 + seed)
    f_obs = f_true * (1.0 + np.asarray(FREQ_SCATTER)[None] * rng.standard_normal(f_true.shape))
    assert shapes is not None
    phi = shapes[None] + SHAPE_NOISE * rng.standard_normal((n_windows, N_MODES, len(sensors)))
    times = (camp.window_starts_ns - camp.window_starts_ns[0]) / 1e9
    return ModalObservations(times=times, mode_numbers=list(range(1, N_MODES + 1)), frequencies_hz=f_obs,
                             shapes=phi, sensor_ids=sensors)
