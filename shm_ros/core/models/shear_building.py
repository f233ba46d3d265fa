"""Shear building: lumped floor masses joined by story springs, one horizontal direction.

Floors are listed bottom-up; ``floors[i]`` is floor ``i + 1`` with its mass and the stiffness of
the story below it. Floor 0 is the ground: it is not a DOF but the base whose acceleration drives
the building. DOFs are floor displacements relative to the ground, so the equation of motion is
``M u'' + C u' + K u = -M r a_g`` with the influence vector ``r`` = ones (``base_influence``) and
a floor sensor reads the absolute acceleration ``u'' + a_g``.
"""

from __future__ import annotations

import numpy as np

from shm_ros.core.models.base import AffineModel, assemble_model
from shm_ros.core.structure import StructureError, StructureSpec


def story_stiffness_matrix(n_floors: int, story: int, k: float = 1.0) -> np.ndarray:
    """Contribution of the story below floor ``story + 1`` (0-based ``story``) with stiffness k."""
    K = np.zeros((n_floors, n_floors))
    K[story, story] += k
    if story > 0:
        K[story - 1, story - 1] += k
        K[story - 1, story] -= k
        K[story, story - 1] -= k
    return K


def build_shear_building(
    spec: StructureSpec, direction: str | None = None, include_parameters: bool = True
) -> AffineModel:
    """Affine shear-building model of ``spec`` for horizontal ``direction`` (``x`` or ``y``).

    The default direction is ``x`` if any sensor measures x, else ``y``. Sensors of the other
    direction are not observed by this model; floor-0 sensors are the ground (base input).
    """
    b = spec.shear_building
    if b is None:
        raise StructureError("not a shear-building structure", spec.source, "kind")
    if direction is None:
        direction = "x" if any(s.direction == "x" for s in spec.sensors) or not spec.sensors else "y"
    if direction not in ("x", "y"):
        raise ValueError(f"direction must be 'x' or 'y', got {direction!r}")
    n = b.n_floors
    params = spec.parameters if include_parameters else []
    k_owner = [-1] * n
    m_owner = [-1] * n
    damping_factors: list[list[int]] = []
    for i, p in enumerate(params):
        dmp: list[int] = []
        for loc in p.targets:
            if loc[:2] == ("shear_building", "floors"):
                (k_owner if loc[-1] == "stiffness" else m_owner)[loc[2]] = i
            elif loc[:2] == ("damping", "ratios"):
                dmp.append(loc[2])
        damping_factors.append(dmp)

    K0 = np.zeros((n, n))
    M0 = np.zeros((n, n))
    K_terms = [np.zeros((n, n)) for _ in params]
    M_terms = [np.zeros((n, n)) for _ in params]
    for i, f in enumerate(b.floors):
        (K0 if k_owner[i] < 0 else K_terms[k_owner[i]])[:, :] += story_stiffness_matrix(n, i, f.stiffness)
        (M0 if m_owner[i] < 0 else M_terms[m_owner[i]])[i, i] += f.mass

    sensor_dofs: dict[str, int] = {}
    for s in spec.sensors:
        if s.direction == direction and s.floor is not None and s.floor >= 1:
            sensor_dofs[s.id] = s.floor - 1
    input_dof = None
    if spec.input_sensor is not None:
        fl = spec.sensor(spec.input_sensor).floor
        input_dof = None if not fl else fl - 1

    return assemble_model(spec, params, K0, M0, K_terms, M_terms,
                          [f"floor{i + 1}.{direction}" for i in range(n)], sensor_dofs,
                          damping_factors, input_dof=input_dof, base_influence=np.ones(n),
                          kind="shear_building", direction=direction)
