"""Synthetic structures and modal data for the updating tests and benchmark.

The data come from a model that is not the analysis model: the girder's from a mesh four times
finer, the building's from the full 8-DOF model while the analysis reduces it to the instrumented
floors by IIRS; frequency noise (per mode, 0.3-1 %) and shape noise (2 % of the unit-max shape) are
drawn independently for every window.
"""

from __future__ import annotations

import os

import numpy as np

from shm_ros.core.models import build_model
from shm_ros.core.observations import ModalObservations
from shm_ros.core.structure import structure_from_dict

FULL = os.environ.get("SHM_FULL", "") not in ("", "0")
FREQ_NOISE = (0.003, 0.005, 0.008, 0.01)
SHAPE_NOISE = 0.02


def building_dict(n_floors: int = 8, sensors=(2, 4, 6, 8)) -> dict:
    return {
        "name": "eight-story",
        "kind": "shear_building",
        "shear_building": {"floors": [{"mass": 4.0e5, "stiffness": 6.0e8} for _ in range(n_floors)]},
        "damping": {"kind": "rayleigh", "ratios": [0.02, 0.02]},
        "sensors": [{"id": f"f{i}", "at": {"floor": i}, "direction": "x"} for i in sensors]
        + [{"id": "g0", "at": {"floor": 0}, "direction": "x"}],
        "input": {"sensor": "g0"},
        "parameters": [
            {"name": "k_low", "applies_to": "shear_building.floors[0,1,2].stiffness",
             "prior": {"dist": "normal", "mean": 1.0, "std": 0.15}},
            {"name": "k_mid", "applies_to": "shear_building.floors[3,4,5].stiffness",
             "prior": {"dist": "normal", "mean": 1.0, "std": 0.15}},
            {"name": "k_top", "applies_to": "shear_building.floors[6,7].stiffness",
             "prior": {"dist": "normal", "mean": 1.0, "std": 0.15}},
        ],
    }


def girder_dict(elements_per_span: int = 20, prior: dict | None = None) -> dict:
    """Three-span girder (60 elements at 20 per span) on soft-ish bearings, 6 deck sensors."""
    prior = prior or {"dist": "normal", "mean": 1.0, "std": 0.15}
    return {
        "name": "three-span-girder",
        "kind": "girder",
        "girder": {
            "spans": [14.0, 30.0, 14.0], "elements_per_span": elements_per_span,
            "section": {"E": 3.4e10, "I": 2.1, "A": 5.2, "rho": 2500},
            "bearings": [{"x": x, "k_vertical": 4.0e8, "k_rotation": 0.0}
                         for x in (0.0, 14.0, 44.0, 58.0)],
        },
        "damping": {"kind": "rayleigh", "ratios": [0.02, 0.02]},
        "sensors": [{"id": f"s{i}", "at": {"x": x}, "direction": "vertical"}
                    for i, x in enumerate((7.0, 19.0, 29.0, 39.0, 51.0, 56.0), start=1)],
        "parameters": [
            {"name": "E_scale", "applies_to": "girder.section.E", "prior": dict(prior)},
            {"name": "k_bearing", "applies_to": "girder.bearings[*].k_vertical", "prior": dict(prior)},
        ],
    }


def spec_and_model(d: dict, **overrides):
    spec = structure_from_dict(d)
    return spec, build_model(spec, **overrides)


def synth_modal(truth_model, theta: np.ndarray, sensor_ids: list[str], n_windows: int,
                rng: np.random.Generator, n_modes: int = 4, freq_noise=FREQ_NOISE,
                shape_noise: float = SHAPE_NOISE) -> ModalObservations:
    """Tracked modal data of ``n_windows`` windows from ``truth_model`` at ``theta``."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1, "blas"):
        sol = truth_model.modes(np.asarray(theta, dtype=float), n_modes)
    S = truth_model.sensor_matrix(sensor_ids)
    phi = (S @ sol.shapes).T  # (modes, sensors)
    k = np.argmax(np.abs(phi), axis=1)
    phi = phi / phi[np.arange(n_modes), k][:, None]  # largest component +1 (docs/interfaces.md §3)
    fn = np.asarray(freq_noise, dtype=float)[:n_modes]
    f = sol.frequencies_hz[None] * (1.0 + fn[None] * rng.standard_normal((n_windows, n_modes)))
    shapes = phi[None] + shape_noise * rng.standard_normal((n_windows, n_modes, len(sensor_ids)))
    return ModalObservations(times=600.0 * np.arange(n_windows), mode_numbers=list(range(1, n_modes + 1)),
                             frequencies_hz=f, shapes=shapes, sensor_ids=list(sensor_ids),
                             covariates={"temperature_c": 10 + rng.standard_normal(n_windows)})
