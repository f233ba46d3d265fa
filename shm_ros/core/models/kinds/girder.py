"""Girder on bearings (``kind: girder``): a multi-span Euler-Bernoulli beam on vertical and
rotational bearing springs, vertical bending only.

The mesh has ``elements_per_span`` equal elements per span, plus nodes wherever a bearing or (by
default) a sensor sits, so span ends, supports and sensors are nodes. With ``sensor_nodes=False`` a
sensor between nodes is read through the Hermite shape functions instead, so the observation matrix
is a general one (``AffineModel.sensor_rows``). Element matrices: :mod:`shm_ros.core.models.beam`.

Structure-file section (docs/interfaces.md section 2)::

    girder:
      spans: [20.0, 30.0]           # m, left to right
      elements_per_span: 10
      section: {E: 3.4e10, I: 0.9, A: 4.0, rho: 2500}    # or a list, one per span
      bearings: [{x: 0, k_vertical: 5e9, k_rotation: 0}, ...]

Sensors sit at ``at: {x: m}`` and measure ``vertical``.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from shm_ros.core.models.base import AffineModel, assemble_model, damping_factors_of
from shm_ros.core.models.beam import beam_mass, beam_stiffness, deck_observation
from shm_ros.core.models.registry import ModelKind, register
from shm_ros.core.structure import FieldReader, Location, StructureError, StructureSpec

SECTION_FIELDS = ("E", "I", "A", "rho")
BEARING_FIELDS = ("x", "k_vertical", "k_rotation")


@dataclass
class SectionSpec:
    """Cross-section and material of a beam span (SI: Pa, m^4, m^2, kg/m^3)."""

    E: float
    I: float  # noqa: E741 - the usual name of the second moment of area
    A: float
    rho: float

    @property
    def EI(self) -> float:
        return self.E * self.I

    @property
    def mass_per_length(self) -> float:
        return self.rho * self.A


@dataclass
class BearingSpec:
    """A support at ``x`` (m from the left end): vertical (N/m) and rotational (N m/rad) springs."""

    x: float
    k_vertical: float
    k_rotation: float = 0.0


@dataclass
class GirderSpec:
    """2-D Euler-Bernoulli girder on bearings. ``sections`` has one entry per span.

    ``section_per_span`` records whether the file gave a list (one per span) or one section for all
    (then ``sections`` holds the same values repeated, and a path ``girder.section.E`` acts on all).
    """

    spans: list[float]
    elements_per_span: int
    sections: list[SectionSpec]
    bearings: list[BearingSpec]
    section_per_span: bool = False

    @property
    def length(self) -> float:
        return float(sum(self.spans))

    def span_ends(self) -> np.ndarray:
        """x of the span boundaries, (n_spans + 1,), starting at 0."""
        return np.concatenate([[0.0], np.cumsum(self.spans)])


@register("girder")
class Girder(ModelKind):
    title = "girder on bearings"

    def parse_section(self, r: FieldReader, value: Any, arrays: Mapping[str, np.ndarray] | None) -> GirderSpec:
        return _parse_girder(r, value)

    def n_dof(self, section: GirderSpec) -> int:
        """Two per node: the spans' divisions, their ends and a node at each bearing."""
        return 2 * (len(section.spans) * section.elements_per_span + 1 + len(section.bearings))

    def section_to_dict(self, section: GirderSpec) -> dict[str, Any]:
        g = section
        secs = [{"E": float(s.E), "I": float(s.I), "A": float(s.A), "rho": float(s.rho)} for s in g.sections]
        return {
            "spans": [float(v) for v in g.spans],
            "elements_per_span": int(g.elements_per_span),
            # one mapping for all spans unless the file had a list or the spans now differ
            "section": secs if g.section_per_span or any(x != secs[0] for x in secs) else secs[0],
            "bearings": [
                {"x": float(b.x), "k_vertical": float(b.k_vertical), "k_rotation": float(b.k_rotation)}
                for b in g.bearings
            ],
        }

    def sensor_location(self, r: FieldReader, section: GirderSpec, at: Mapping[str, Any], direction: str,
                        fld: str) -> dict[str, Any]:
        r.keys(at, ("x",), ("x",), f"{fld}.at")
        x = r.number(at["x"], f"{fld}.at.x")
        if not -1e-9 <= x <= section.length * (1 + 1e-9):
            raise r.err(f"x = {x} is outside the girder [0, {section.length}]", f"{fld}.at.x")
        if direction != "vertical":
            raise r.err("a girder sensor must be vertical", f"{fld}.direction")
        return {"x": x}

    def updatable(self, loc: Location) -> bool:
        if loc[:2] == ("girder", "section"):
            return loc[-1] in SECTION_FIELDS and len(loc) in (3, 4)
        if loc[:2] == ("girder", "bearings") and len(loc) == 4:
            return loc[-1] in ("k_vertical", "k_rotation")
        return False

    def product_keys(self, section: GirderSpec, loc: Location) -> list[tuple]:
        # E and I share the bending stiffness of a span, rho and A its mass: two factors on them
        # would make the model non-affine
        if loc[:2] == ("girder", "section"):
            spans = [loc[2]] if len(loc) == 4 else list(range(len(section.spans)))
            term = "EI" if loc[-1] in ("E", "I") else "rhoA"
            return [("girder", term, k) for k in spans]
        return [loc]

    def default_sensors(self, section: GirderSpec) -> list[dict[str, Any]]:
        """Quarter points of every span, vertical."""
        ends = section.span_ends()
        xs = [float(a + f * (b - a)) for a, b in zip(ends[:-1], ends[1:], strict=True) for f in (0.25, 0.5, 0.75)]
        return [{"id": f"s{i + 1}", "at": {"x": round(x, 6)}, "direction": "vertical"} for i, x in enumerate(xs)]

    def build(self, spec: StructureSpec, **overrides: Any) -> AffineModel:
        """Overrides: ``elements_per_span``, ``sensor_nodes``, ``include_parameters`` (:func:`build_girder`)."""
        return build_girder(spec, **overrides)


def _section(r: FieldReader, v: Any, fld: str) -> SectionSpec:
    m = r.mapping(v, fld)
    r.keys(m, SECTION_FIELDS, SECTION_FIELDS, fld)
    return SectionSpec(**{k: r.number(m[k], f"{fld}.{k}", positive=True) for k in SECTION_FIELDS})


def _parse_girder(r: FieldReader, v: Any) -> GirderSpec:
    g = r.mapping(v, "girder")
    r.keys(g, ("spans", "elements_per_span", "section", "bearings"), ("spans", "section", "bearings"), "girder")
    spans = [
        r.number(s, f"girder.spans[{i}]", positive=True) for i, s in enumerate(r.seq(g["spans"], "girder.spans"))
    ]
    if not spans:
        raise r.err("needs at least one span", "girder.spans")
    eps = r.integer(g.get("elements_per_span", 10), "girder.elements_per_span", minimum=1)
    sec = g["section"]
    if isinstance(sec, list):
        if len(sec) != len(spans):
            raise r.err(f"has {len(sec)} entries but there are {len(spans)} spans", "girder.section")
        sections = [_section(r, s, f"girder.section[{i}]") for i, s in enumerate(sec)]
        per_span = True
    else:
        one = _section(r, sec, "girder.section")
        sections = [copy.copy(one) for _ in spans]
        per_span = False
    length = sum(spans)
    bearings = []
    for i, b in enumerate(r.seq(g["bearings"], "girder.bearings")):
        fld = f"girder.bearings[{i}]"
        b = r.mapping(b, fld)
        r.keys(b, BEARING_FIELDS, ("x", "k_vertical"), fld)
        x = r.number(b["x"], f"{fld}.x")
        if not -1e-9 * length <= x <= length * (1 + 1e-9):
            raise r.err(f"x = {x} is outside the girder [0, {length}]", f"{fld}.x")
        bearings.append(
            BearingSpec(
                x=min(max(x, 0.0), length),
                k_vertical=r.number(b["k_vertical"], f"{fld}.k_vertical", nonneg=True),
                k_rotation=r.number(b.get("k_rotation", 0.0), f"{fld}.k_rotation", nonneg=True),
            )
        )
    n_vertical = sum(1 for b in bearings if b.k_vertical > 0)
    if n_vertical < 1 or (n_vertical < 2 and not any(b.k_rotation > 0 for b in bearings)):
        raise r.err(
            "the girder needs at least two vertical bearings (or one with rotational stiffness)", "girder.bearings"
        )
    return GirderSpec(
        spans=spans, elements_per_span=eps, sections=sections, bearings=bearings, section_per_span=per_span
    )


@dataclass
class GirderMesh:
    """Node coordinates and, per element, its nodes' indices, length and span."""

    node_x: np.ndarray  # (n_nodes,)
    element_span: np.ndarray  # (n_elements,) span index of each element

    @property
    def n_nodes(self) -> int:
        return len(self.node_x)

    @property
    def n_elements(self) -> int:
        return len(self.node_x) - 1

    @property
    def element_length(self) -> np.ndarray:
        return np.diff(self.node_x)

    def node_at(self, x: float, tol: float) -> int | None:
        i = int(np.argmin(np.abs(self.node_x - x)))
        return i if abs(self.node_x[i] - x) <= tol else None


def girder_mesh(g: GirderSpec, extra_x: list[float] | None = None, elements_per_span: int | None = None) -> GirderMesh:
    """Nodes: ``elements_per_span`` equal divisions of each span, plus bearings and ``extra_x``.

    Span ends and bearings are fixed nodes. An extra point (a sensor) within 1e-6 of the shortest
    element of a node is that node; one within a quarter element of an interior mesh node moves that
    node onto it (so no sliver elements appear); otherwise a node is inserted.
    """
    n = elements_per_span or g.elements_per_span
    ends = g.span_ends()
    base = np.unique(np.concatenate([np.linspace(ends[k], ends[k + 1], n + 1) for k in range(len(g.spans))]))
    h_min = float(np.min(np.diff(base)))
    tol = 1e-6 * h_min
    fixed = list(ends)
    for b in g.bearings:
        if np.min(np.abs(np.asarray(fixed) - b.x)) > tol:
            fixed.append(float(b.x))
    pts = sorted(set([float(x) for x in base if np.min(np.abs(np.asarray(fixed) - x)) > tol] + fixed))
    is_fixed = {x: np.min(np.abs(np.asarray(fixed) - x)) <= tol for x in pts}
    moved: set[float] = set()
    for x in sorted(extra_x or []):
        arr = np.asarray(pts)
        i = int(np.argmin(np.abs(arr - x)))
        dx = abs(arr[i] - x)
        if dx <= tol:
            continue
        local_h = float(np.min(np.diff(arr[max(i - 1, 0) : i + 2]))) if len(arr) > 1 else h_min
        if not is_fixed[pts[i]] and pts[i] not in moved and dx < 0.25 * local_h:
            old = pts[i]
            pts[i] = float(x)
            del is_fixed[old]
            is_fixed[pts[i]] = False
            moved.add(pts[i])
            pts.sort()
        else:
            pts.append(float(x))
            is_fixed[float(x)] = True  # an inserted sensor node is not moved again
            pts.sort()
    node_x = np.array(pts)
    mids = 0.5 * (node_x[:-1] + node_x[1:])
    span = np.clip(np.searchsorted(ends, mids, side="right") - 1, 0, len(g.spans) - 1)
    return GirderMesh(node_x=node_x, element_span=span)


def build_girder(
    spec: StructureSpec,
    elements_per_span: int | None = None,
    sensor_nodes: bool = True,
    include_parameters: bool = True,
) -> AffineModel:
    """Affine girder model of ``spec`` (kind ``girder``).

    ``elements_per_span`` overrides the file's value (e.g. a finer truth model); ``sensor_nodes``
    puts a node at every sensor (default) or reads sensors by shape functions when False.
    ``include_parameters=False`` builds the nominal model with no parameters.
    """
    g = spec.section
    if not isinstance(g, GirderSpec):
        raise StructureError("not a girder structure", spec.source, "kind")
    extra = [s.x for s in spec.sensors if s.x is not None] if sensor_nodes else []
    mesh = girder_mesh(g, extra, elements_per_span)
    n_dof = 2 * mesh.n_nodes
    L_all = mesh.element_length
    tol = 1e-6 * float(L_all.min())

    params = spec.parameters if include_parameters else []
    n_spans = len(g.spans)

    # which parameter carries EI / rhoA of each span, which bearing spring
    ei_owner = [-1] * n_spans
    ma_owner = [-1] * n_spans
    kv_owner = [-1] * len(g.bearings)
    kr_owner = [-1] * len(g.bearings)
    for i, p in enumerate(params):
        for loc in p.targets:
            if loc[:2] == ("girder", "section"):
                spans = [int(loc[2])] if len(loc) == 4 else list(range(n_spans))
                owner = ei_owner if loc[-1] in ("E", "I") else ma_owner
                for k in spans:
                    owner[k] = i
            elif loc[:2] == ("girder", "bearings"):
                (kv_owner if loc[-1] == "k_vertical" else kr_owner)[int(loc[2])] = i

    K0 = np.zeros((n_dof, n_dof))
    M0 = np.zeros((n_dof, n_dof))
    K_terms = [np.zeros((n_dof, n_dof)) for _ in params]
    M_terms = [np.zeros((n_dof, n_dof)) for _ in params]

    for e in range(mesh.n_elements):
        k = int(mesh.element_span[e])
        sec = g.sections[k]
        Le = float(L_all[e])
        sl = slice(2 * e, 2 * e + 4)
        ke = beam_stiffness(sec.EI, Le)
        me = beam_mass(sec.mass_per_length, Le)
        (K0 if ei_owner[k] < 0 else K_terms[ei_owner[k]])[sl, sl] += ke
        (M0 if ma_owner[k] < 0 else M_terms[ma_owner[k]])[sl, sl] += me

    for j, b in enumerate(g.bearings):
        node = mesh.node_at(b.x, tol)
        assert node is not None  # bearings are always nodes of the mesh
        (K0 if kv_owner[j] < 0 else K_terms[kv_owner[j]])[2 * node, 2 * node] += b.k_vertical
        (K0 if kr_owner[j] < 0 else K_terms[kr_owner[j]])[2 * node + 1, 2 * node + 1] += b.k_rotation

    labels = []
    for x in mesh.node_x:
        labels += [f"w@{x:.6g}", f"r@{x:.6g}"]

    sensor_dofs: dict[str, int] = {}
    sensor_rows: dict[str, np.ndarray] = {}
    for s in spec.sensors:
        x = float(s.at["x"])  # every girder sensor has one (``sensor_location``)
        sensor_rows[s.id] = deck_observation(mesh.node_x, [x])[0]
        node = mesh.node_at(x, tol)
        if node is not None:
            sensor_dofs[s.id] = 2 * node
            sensor_rows[s.id] = np.zeros(n_dof)
            sensor_rows[s.id][2 * node] = 1.0

    return assemble_model(spec, params, K0, M0, K_terms, M_terms, labels, sensor_dofs,
                          damping_factors_of(params), base_influence=None, sensor_rows=sensor_rows,
                          kind="girder", direction="vertical", node_x=mesh.node_x.copy())


