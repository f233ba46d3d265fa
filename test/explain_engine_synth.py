"""Modal tables for the explain engine's tests: the simulator's girder truth per window, no signals.

The truth is the ``girder`` scenario's campaign truth with its default model-form error (Timoshenko
deck with lateral and torsional families, scattered properties, misplaced sensors, rotational
restraint at the bearings) - outside the analysis model's class. Per window the true in-plane
frequencies come from ``truth_model.system(campaign.factors(i))`` on a grid of the effect's factor
(interpolated per window: the eigen-solution of the fine truth costs more than the test may spend),
scattered by 0.3 % per mode; shapes carry 2 % noise; the covariate is the campaign's measured
temperature. ``effect`` None gives a clean table (no hidden effect).
"""

from __future__ import annotations

import numpy as np

from shm_ros.core.observations import ModalObservations
from shm_ros.core.simulate.campaign import simulate_campaign
from shm_ros.core.simulate.scenario import EffectRequest, named_scenario
from shm_ros.core.structure import structure_from_dict

N_MODES = 4
FREQ_SCATTER = 0.003
SHAPE_NOISE = 0.02


def engine_table(seed: int, n_windows: int, effect: tuple[str, dict] | None, window_s: float = 600.0):
    """(obs, nominal spec, truth: {"factor": (W,) factor of the effect's group, "group": name})."""
    sc = named_scenario("girder", n_windows=n_windows, window_s=window_s, pause_s=2.0, seed=seed)
    sc.effects = [] if effect is None else [EffectRequest(effect[0], dict(effect[1]))]
    camp = simulate_campaign(sc)
    tm = camp.truth_model
    factors = [camp.factors(i) for i in range(n_windows)]
    keys = sorted({k for f in factors for k in f})
    sensors = list(camp.nominal_structure["sensors"])
    sensor_ids = [s["id"] for s in sensors]
    rows = [tm.sensor_ids.index(s) for s in sensor_ids]
    if keys:
        key = keys[0]
        values = np.array([f.get(key, 1.0) for f in factors])
        uniq = np.unique(values)
        grid = uniq if uniq.size <= 9 else np.linspace(values.min(), values.max(), 9)
    else:
        key, values, grid = "", np.ones(n_windows), np.ones(1)
    freqs, shapes = [], None
    for g in grid:
        _, modal = tm.system({key: float(g)} if key else {})
        idx = modal.in_plane()[:N_MODES]
        freqs.append(np.asarray(modal.frequencies_hz)[idx])
        if shapes is None:
            shapes = np.asarray(modal.shapes)[rows][:, idx].T
    fa = np.array(freqs)
    if grid.size > 1:
        f_true = np.column_stack([np.interp(values, grid, fa[:, k]) for k in range(N_MODES)])
    else:
        f_true = np.repeat(fa, n_windows, axis=0)
    rng = np.random.default_rng(50_000 + seed)
    f_obs = f_true * (1.0 + FREQ_SCATTER * rng.standard_normal(f_true.shape))
    assert shapes is not None
    phi = shapes[None] + SHAPE_NOISE * rng.standard_normal((n_windows, N_MODES, len(sensor_ids)))
    temps = np.array([camp.measured_temperature(i) for i in range(n_windows)], dtype=float)
    times = camp.window_starts_ns / 1e9
    obs = ModalObservations(times=times, mode_numbers=list(range(1, N_MODES + 1)), frequencies_hz=f_obs,
                            shapes=phi, sensor_ids=sensor_ids, covariates={"temperature_c": temps},
                            time_kind="iso")
    spec = structure_from_dict(camp.nominal_structure)
    return obs, spec, {"group": key, "factor": values,
                       "effect": None if effect is None else camp.effects[0].describe()}
