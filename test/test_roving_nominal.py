"""The nominal model at a roving structure's points (shm_ros/core/roving/nominal.py): modal masses on
the points' unit-max scale, against a hand computation, and the one-to-one assignment of identified
modes to the modes of interest by shape and frequency, whatever their order."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from shm_ros.core.roving.nominal import NominalAtPoints
from shm_ros.io.structure import load_structure

SPEC = load_structure(Path(__file__).resolve().parents[1] / "examples" / "girder_roving.yaml")


def test_modal_mass_on_the_points_scale():
    nom = NominalAtPoints(SPEC, 3)
    model = SPEC.model_kind.build(SPEC)
    sol = model.modes(n_modes=3)
    ids = [p.id for p in SPEC.measurement_points]
    rows = np.array([model.location_row(p.at) for p in SPEC.measurement_points])
    for j in range(3):
        v = sol.shapes[:, j] / np.max(np.abs(rows @ sol.shapes[:, j]))  # largest component over the points: 1
        assert nom.unit_max_modal_mass(ids)[j] == pytest.approx(float(v @ model.mass() @ v), rel=1e-10)
    # ids the model cannot read are left out, not an error
    assert np.allclose(nom.unit_max_modal_mass(ids + ["r1"]), nom.unit_max_modal_mass(ids))


def test_assignment_by_shape_and_frequency_in_any_order():
    nom = NominalAtPoints(SPEC, 3)
    ids = [s.id for s in SPEC.sensors] + [p.id for p in SPEC.measurement_points]
    phi = nom.shapes(ids)
    shapes = [dict(zip(ids, phi[:, j], strict=True)) for j in range(3)]
    f = list(nom.frequencies_hz * np.array([0.97, 0.95, 1.04]))  # model-form error within the gate
    # listed in another order, with a mode the model does not have (a lateral one: no vertical shape)
    order = [2, 0, 1]
    lateral = dict(zip(ids, np.random.default_rng(0).normal(size=len(ids)), strict=True))
    got = nom.assign([f[k] for k in order] + [nom.frequencies_hz[0] * 0.9],
                     [shapes[k] for k in order] + [lateral])
    assert got == {0: 2, 1: 0, 2: 1}
    # a frequency outside the gate is not assigned
    assert nom.assign([nom.frequencies_hz[0] * 1.3], [shapes[0]]) == {}
