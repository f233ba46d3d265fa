"""Shear building: lumped floor masses joined by story springs, one horizontal direction.

Floors are listed bottom-up; ``floors[i]`` is floor ``i + 1`` with its mass and the stiffness of
the story below it. Floor 0 is the ground: it is not a DOF but the base whose acceleration drives
the building. DOFs are floor displacements relative to the ground, so the equation of motion is
``M u'' + C u' + K u = -M r a_g`` with the influence vector ``r`` = ones (``base_influence``) and
a floor sensor reads the absolute acceleration ``u'' + a_g``.

Structure-file section (``kind: shear_building``, docs/interfaces.md section 2)::

    shear_building:
      floors: [{mass: 2.0e5, stiffness: 3.0e8, height: 3.5}, ...]   # kg, N/m, m; floor 1 first
      dampers:                                                        # optional
        - {between: [0, 1], c: 2.0e6}                     # Kelvin-Voigt dashpot, N s/m
        - {between: [1, 2], c: 2.0e6, k_maxwell: 4.0e7}   # Maxwell: spring in series, N/m

Sensors sit at ``at: {floor: k}`` (0 = ground) and measure ``x`` or ``y``. ``height`` (optional) is
the story below the floor, for drift ratios. A damper joins two floors (0 = ground) and acts in the
model's direction; dampers make the damping non-classical (``AffineModel.damping`` holds the
Kelvin-Voigt dashpots, a Maxwell element's force is a state of the time-domain response).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shm_ros.core.models.base import AffineModel, Damper, assemble_model, damping_factors_of
from shm_ros.core.models.registry import ModelKind, register
from shm_ros.core.structure import FieldReader, Location, StructureError, StructureSpec

FLOOR_FIELDS = ("mass", "stiffness")  # the updatable ones
DAMPER_FIELDS = ("between", "c", "k_maxwell")


@dataclass
class FloorSpec:
    """One floor of a shear building: its lumped mass (kg), the stiffness of the story below (N/m)
    and, optionally, that story's height (m)."""

    mass: float
    stiffness: float
    height: float | None = None


@dataclass
class DamperSpec:
    """A damper between floors ``between`` (0 = ground): dashpot ``c`` (N s/m), with ``k_maxwell``
    (N/m) a Maxwell element (spring in series with the dashpot)."""

    between: tuple[int, int]
    c: float
    k_maxwell: float | None = None


@dataclass
class ShearBuildingSpec:
    """Floors bottom-up (floor 1 first); floor 0 is the ground and is not listed."""

    floors: list[FloorSpec]
    dampers: list[DamperSpec] = field(default_factory=list)

    @property
    def n_floors(self) -> int:
        return len(self.floors)


@register("shear_building")
class ShearBuilding(ModelKind):
    title = "shear building"

    def n_dof(self, section: ShearBuildingSpec) -> int:
        return section.n_floors

    def parse_section(self, r: FieldReader, value: Any, arrays: Mapping[str, np.ndarray] | None
                      ) -> ShearBuildingSpec:
        b = r.mapping(value, "shear_building")
        r.keys(b, ("floors", "dampers"), ("floors",), "shear_building")
        floors = []
        for i, f in enumerate(r.seq(b["floors"], "shear_building.floors")):
            fld = f"shear_building.floors[{i}]"
            f = r.mapping(f, fld)
            r.keys(f, (*FLOOR_FIELDS, "height"), FLOOR_FIELDS, fld)
            floors.append(
                FloorSpec(
                    mass=r.number(f["mass"], f"{fld}.mass", positive=True),
                    stiffness=r.number(f["stiffness"], f"{fld}.stiffness", positive=True),
                    height=None if f.get("height") is None else r.number(f["height"], f"{fld}.height", positive=True),
                )
            )
        if not floors:
            raise r.err("needs at least one floor", "shear_building.floors")
        dampers = [_damper(r, d, f"shear_building.dampers[{i}]", len(floors))
                   for i, d in enumerate(r.seq(b.get("dampers") or [], "shear_building.dampers"))]
        return ShearBuildingSpec(floors=floors, dampers=dampers)

    def section_to_dict(self, section: ShearBuildingSpec) -> dict[str, Any]:
        floors = []
        for f in section.floors:
            d = {"mass": float(f.mass), "stiffness": float(f.stiffness)}
            if f.height is not None:
                d["height"] = float(f.height)
            floors.append(d)
        out: dict[str, Any] = {"floors": floors}
        if section.dampers:
            out["dampers"] = [{"between": list(d.between), "c": float(d.c),
                               **({} if d.k_maxwell is None else {"k_maxwell": float(d.k_maxwell)})}
                              for d in section.dampers]
        return out

    def sensor_location(self, r: FieldReader, section: ShearBuildingSpec, at: Mapping[str, Any], direction: str,
                        fld: str) -> dict[str, Any]:
        r.keys(at, ("floor",), ("floor",), f"{fld}.at")
        fl = r.integer(at["floor"], f"{fld}.at.floor", minimum=0)
        if fl > section.n_floors:
            raise r.err(f"floor {fl} does not exist (the building has {section.n_floors} floors)", f"{fld}.at.floor")
        if direction == "vertical":
            raise r.err("a shear-building sensor must be horizontal (x or y)", f"{fld}.direction")
        return {"floor": fl}

    def updatable(self, loc: Location) -> bool:
        return loc[:2] == ("shear_building", "floors") and len(loc) == 4 and loc[-1] in FLOOR_FIELDS

    def default_sensors(self, section: ShearBuildingSpec) -> list[dict[str, Any]]:
        """The ground and every floor, direction x."""
        return [{"id": "g0" if k == 0 else f"f{k}", "at": {"floor": k}, "direction": "x"}
                for k in range(section.n_floors + 1)]

    def build(self, spec: StructureSpec, **overrides: Any) -> AffineModel:
        """Overrides: ``direction``, ``include_parameters`` (:func:`build_shear_building`)."""
        return build_shear_building(spec, **overrides)


def _damper(r: FieldReader, value: Any, fld: str, n_floors: int) -> DamperSpec:
    d = r.mapping(value, fld)
    r.keys(d, DAMPER_FIELDS, ("between", "c"), fld)
    between = r.seq(d["between"], f"{fld}.between")
    if len(between) != 2:
        raise r.err(f"must name two floors [i, j], got {len(between)} entries", f"{fld}.between")
    ends = tuple(r.integer(v, f"{fld}.between[{k}]", minimum=0) for k, v in enumerate(between))
    for k, e in enumerate(ends):
        if e > n_floors:
            raise r.err(f"floor {e} does not exist (the building has {n_floors} floors; 0 is the ground)",
                        f"{fld}.between[{k}]")
    if ends[0] == ends[1]:
        raise r.err(f"a damper joins two different floors, got [{ends[0]}, {ends[1]}]", f"{fld}.between")
    c = r.number(d["c"], f"{fld}.c", positive=True)
    km = None if d.get("k_maxwell") is None else r.number(d["k_maxwell"], f"{fld}.k_maxwell", positive=True)
    return DamperSpec(between=(ends[0], ends[1]), c=c, k_maxwell=km)


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
    b = spec.section
    if not isinstance(b, ShearBuildingSpec):
        raise StructureError("not a shear-building structure", spec.source, "kind")
    if direction is None:
        direction = "x" if any(s.direction == "x" for s in spec.sensors) or not spec.sensors else "y"
    if direction not in ("x", "y"):
        raise ValueError(f"direction must be 'x' or 'y', got {direction!r}")
    n = b.n_floors
    params = spec.parameters if include_parameters else []
    k_owner = [-1] * n
    m_owner = [-1] * n
    for i, p in enumerate(params):
        for loc in p.targets:
            if loc[:2] == ("shear_building", "floors"):
                (k_owner if loc[-1] == "stiffness" else m_owner)[int(loc[2])] = i

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

    dampers = [Damper(nodes=(_dof(d.between[0]), _dof(d.between[1])), c=d.c, k_maxwell=d.k_maxwell)
               for d in b.dampers]
    heights = [f.height for f in b.floors]
    return assemble_model(spec, params, K0, M0, K_terms, M_terms,
                          [f"floor{i + 1}.{direction}" for i in range(n)], sensor_dofs,
                          damping_factors_of(params), input_dof=input_dof, base_influence=np.ones(n),
                          kind="shear_building", direction=direction, dampers=dampers,
                          ground_sensors=[s.id for s in spec.sensors if s.direction == direction and s.floor == 0],
                          story_heights=None if None in heights else np.asarray(heights, dtype=float))


def _dof(floor: int) -> int | None:
    """DOF index of a floor; None for the ground."""
    return None if floor == 0 else floor - 1
