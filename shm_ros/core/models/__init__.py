"""Structural models: one affine model form, built for each structure kind; reduction and expansion.

``build_model(spec, **overrides)`` is the one entry point: the structure's kind
(:mod:`shm_ros.core.models.registry`, one file per kind in ``kinds/``) maps every ``parameters:``
entry of the structure file to its stiffness/mass term of an :class:`AffineModel`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

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
from shm_ros.core.models.registry import model_kind

if TYPE_CHECKING:  # annotation only: the structure module imports this package's registry
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
    """Affine model of a structure, built by the structure's kind.

    Overrides by kind - girder: ``elements_per_span`` (int), ``sensor_nodes`` (bool, default True:
    a node at each sensor; False: shape-function observation); shear_building: ``direction``
    ("x" | "y"); all: ``include_parameters`` (bool, default True; False = nominal model with no
    parameters). Unknown overrides raise TypeError.
    """
    return model_kind(spec.kind).build(spec, **overrides)
