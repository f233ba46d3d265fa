"""What a response computation returns: quantities at rows over the model's nodes.

A row has one entry per DOF of the model plus a last entry for the ground (floor 0 of a building),
so the absolute motion of a sensor is a unit row and an interstory drift the difference of two
unit rows. Accelerations are absolute; displacements and velocities too (the difference of two is
a drift whatever the supports do).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from shm_ros.core.models.base import AffineModel


class Quantity(StrEnum):
    ACCELERATION = "acceleration"  # m/s^2, absolute
    VELOCITY = "velocity"  # m/s, absolute
    DISPLACEMENT = "displacement"  # m, absolute


@dataclass(frozen=True)
class Output:
    """One output channel: ``quantity`` of ``row @ X`` where X holds the DOFs then the ground."""

    name: str
    quantity: Quantity
    row: np.ndarray  # (n_dof + 1,)


def node_row(model: AffineModel, dof_row: np.ndarray | None) -> np.ndarray:
    """A DOF row (n_dof,) extended by the ground entry; None is the ground itself."""
    row = np.zeros(model.n_dof + 1)
    if dof_row is None:
        row[-1] = 1.0
    else:
        row[:-1] = dof_row
    return row


def sensor_outputs(model: AffineModel, sensor_ids: Sequence[str],
                   quantity: Quantity = Quantity.ACCELERATION) -> list[Output]:
    """``quantity`` at each sensor; a ground sensor (and a base input's sensor) reads the ground."""
    out = []
    for sid in sensor_ids:
        if sid in model.sensor_rows:
            row = node_row(model, model.sensor_rows[sid])
        elif sid in model.ground_sensors or any(i.sensor == sid and i.kind == "base" for i in model.inputs):
            row = node_row(model, None)
        else:
            raise KeyError(f"model {model.name!r} does not observe sensor {sid!r}")
        out.append(Output(sid, quantity, row))
    return out


def drift_outputs(model: AffineModel, ratio: bool = False) -> list[Output]:
    """Interstory drift of every story of a shear building (floor k minus floor k - 1, m); with
    ``ratio`` divided by the story heights (the structure file's ``height``)."""
    if model.kind != "shear_building":
        raise ValueError(f"drifts are defined for shear buildings, model {model.name!r} is a {model.kind}")
    if ratio and model.story_heights is None:
        raise ValueError(f"model {model.name!r}: drift ratios need every floor's 'height'")
    out = []
    for k in range(1, model.n_dof + 1):
        row = np.zeros(model.n_dof + 1)
        row[k - 1] = 1.0
        row[k - 2 if k > 1 else -1] -= 1.0  # the ground is the last entry
        if ratio:
            assert model.story_heights is not None
            row /= model.story_heights[k - 1]
        out.append(Output(f"drift{'_ratio' if ratio else ''}{k}", Quantity.DISPLACEMENT, row))
    return out
