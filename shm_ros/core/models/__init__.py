"""Structural models: girder on bearings, shear building, user matrices; reduction and expansion.

``build_model(spec, **overrides)`` is the one entry point: it maps every ``parameters:`` entry of a
structure file to its stiffness/mass term of an :class:`AffineModel`.
"""

from __future__ import annotations

from typing import Any

from shm_ros.core.models.base import AffineModel, BatchModalSolution, ModalSolution
from shm_ros.core.models.reduction import (
    Reduction,
    expand_mode_shapes,
    expand_sensor_shapes,
    guyan,
    iirs,
    iirs_limit,
    reduce_model,
    reduced_modes_batch,
)
from shm_ros.core.structure import StructureSpec

__all__ = [
    "AffineModel",
    "ModalSolution",
    "BatchModalSolution",
    "build_model",
    "Reduction",
    "iirs",
    "iirs_limit",
    "guyan",
    "reduce_model",
    "reduced_modes_batch",
    "expand_mode_shapes",
    "expand_sensor_shapes",
]


def build_model(spec: StructureSpec, **overrides: Any) -> AffineModel:
    """Affine model of a structure.

    Overrides by kind - girder: ``elements_per_span`` (int), ``sensor_nodes`` (bool, default True:
    a node at each sensor; False: shape-function observation); shear_building: ``direction``
    ("x" | "y"); all: ``include_parameters`` (bool, default True; False = nominal model with no
    parameters). Unknown overrides raise TypeError.
    """
    if spec.kind == "girder":
        from shm_ros.core.models.girder import build_girder

        return build_girder(spec, **overrides)
    if spec.kind == "shear_building":
        from shm_ros.core.models.shear_building import build_shear_building

        return build_shear_building(spec, **overrides)
    if spec.kind == "matrices":
        from shm_ros.core.models.matrices import build_matrices

        return build_matrices(spec, **overrides)
    raise ValueError(f"{spec.source}: unknown structure kind {spec.kind!r}")
