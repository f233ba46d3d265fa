"""A dense (hourly) campaign: per window an OpenSees eigen analysis of the structure's state at that
time, a damping model, the identification-error model, written as a tracked-modes table.

Damping model: Rayleigh, ratios 1-3 % met at the nominal state's modes 1 and 3, evaluated at each
window's true frequencies (so damping follows stiffness a little), plus any effect's added damping.
Covariates written: ``temperature_c`` (the air sensor: air + 0.2 degC noise, NOT the structure's
temperature) and ``rms_accel_m_s2`` (the window's vibration level: traffic/wind, daily cycle).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import dense_effects as fx
from .building import draw_building
from .dense_structures import BuildingStructure, DenseStructure, GirderStructure
from .drivers import air_temperature
from .files import iso, write_table, write_truth, write_yaml
from .girder import draw_girder
from .id_errors import IdErrors

WINDOWS = {"reduced": 500, "full": 2400}   # hourly: three weeks / a hundred days


def structure_for(kind: str, seed: int) -> str:
    if kind in fx.GIRDER_ONLY or kind == "dense_lagged_temperature":
        return "girder"
    if kind == "dense_humidity":
        return "building"
    return "girder" if seed % 2 == 0 else "building"


def _amplitude(rng: np.random.Generator, t_h: np.ndarray) -> np.ndarray:
    day = np.clip(np.sin(np.pi * ((t_h % 24.0) - 6.0) / 16.0), 0.0, None)
    return float(rng.uniform(2e-3, 5e-3)) * (1.0 + 2.0 * day) * np.exp(0.4 * rng.standard_normal(t_h.size))


def generate(kind: str, seed: int, size: str, out: Path) -> dict:
    rng = np.random.default_rng(seed)
    w = WINDOWS[size]
    t_h = np.arange(w, dtype=float)
    air = air_temperature(rng, t_h, start_doy=float(rng.uniform(320.0, 360.0)), mean_c=float(rng.uniform(5.0, 10.0)),
                          season_amp=float(rng.uniform(8.0, 12.0)), daily_amp=float(rng.uniform(3.0, 7.0)),
                          weather_sd=float(rng.uniform(1.5, 3.0)))
    wx = fx.Weather(t_h=t_h, air_c=air, amplitude=_amplitude(rng, t_h))
    which = structure_for(kind, seed)
    structure: DenseStructure
    if which == "girder":
        g = draw_girder(rng)
        structure = GirderStructure(g)
        k_v = g.k_vertical
    else:
        n = 3 if size == "reduced" else int(rng.integers(3, 11))
        structure = BuildingStructure(draw_building(rng, n))
    rng_fx = np.random.default_rng([seed, 1])   # the effect's own stream (common random numbers)
    if kind in fx.GIRDER_ONLY:
        truth = fx.GIRDER_ONLY[kind](rng_fx, wx, which, k_v)
    else:
        truth = fx.ANY[kind](rng_fx, wx, which)
    f = np.empty((w, structure.n_modes))
    phi = np.empty((w, len(structure.sensor_ids), structure.n_modes))
    for i in range(w):
        state = {"e_factor": truth.e_factor[i]}
        if which == "girder":
            state["k_vertical"] = k_v if truth.k_vertical is None else truth.k_vertical[i]
            state["k_rotation"] = np.zeros(4) if truth.k_rotation is None else truth.k_rotation[i]
        f[i], phi[i] = structure.modes(state)
    zeta_r = (float(rng.uniform(0.01, 0.03)), float(rng.uniform(0.01, 0.03)))
    f_nom = np.median(f, axis=0)
    w1, w3 = 2 * np.pi * f_nom[0], 2 * np.pi * f_nom[min(2, f_nom.size - 1)]
    a1 = 2 * (zeta_r[1] * w3 - zeta_r[0] * w1) / (w3**2 - w1**2)
    a0 = 2 * zeta_r[0] * w1 - a1 * w1**2
    omega = 2 * np.pi * f
    zeta = a0 / (2 * omega) + a1 * omega / 2
    if truth.added_damping is not None:
        zeta = zeta + truth.added_damping[:, None]
    errors = IdErrors.draw(rng, structure.n_modes)
    f_id, z_id, p_id, swapped = errors.apply(rng, f, zeta, phi)
    cols: dict[str, np.ndarray] = {}
    for k in range(structure.n_modes):
        cols[f"mode{k + 1}_hz"] = f_id[:, k]
        cols[f"mode{k + 1}_damping"] = z_id[:, k]
        for s, sid in enumerate(structure.sensor_ids):
            cols[f"mode{k + 1}_shape_{sid}"] = p_id[:, s, k]
    cols["temperature_c"] = air + 0.2 * rng.standard_normal(w)
    cols["rms_accel_m_s2"] = wx.amplitude
    out.mkdir(parents=True, exist_ok=True)
    write_table(out / "tracked_modes.csv", t_h * 3600.0, cols)
    write_yaml(structure.nominal(rng, f"truth-{kind}-{seed}", zeta_r), out / "structure.yaml")
    doc = {"kind": kind, "seed": seed, "size": size, "structure": which, "expected": truth.expected,
           "acceptable": list(truth.acceptable), "windows": w, "window_hours": 1.0,
           "start": iso(0.0), "change_window": truth.change_window,
           "change_time": iso(truth.change_window * 3600.0) if truth.change_window is not None else None,
           "effect": truth.record, "stiffness_factor": truth.e_factor, "true_frequencies_hz": f,
           "true_damping": zeta, "rayleigh_ratios": zeta_r, "identification_errors": errors.as_dict(),
           "swapped_windows": np.flatnonzero(swapped.any(axis=1)), "sensor_ids": structure.sensor_ids}
    write_truth(doc, out / "truth.json")
    return doc
