"""Girder on bearings: 2-D Euler-Bernoulli beam elements (vertical bending).

DOFs per node: vertical displacement ``w`` (m, up) and rotation ``r`` (rad). Elements are the
classic two-node Hermite beam with consistent mass; bearings are vertical and rotational springs at
their ``x``. The mesh has ``elements_per_span`` equal elements per span, plus nodes wherever a
bearing or (by default) a sensor sits, so span ends, supports and sensors are nodes. With
``sensor_nodes=False`` a sensor between nodes is read through the Hermite shape functions instead,
so the observation matrix is a general one (``AffineModel.sensor_rows``).

Hand-written because no maintained Python library offers an affine (per-parameter) assembly of a
small beam model; the element matrices are the textbook ones.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shm_ros.core.models.base import AffineModel, assemble_model
from shm_ros.core.structure import GirderSpec, StructureError, StructureSpec


def beam_stiffness(EI: float, L: float) -> np.ndarray:
    """Bending stiffness of one Euler-Bernoulli element, DOFs (w1, r1, w2, r2)."""
    return (EI / L**3) * np.array(
        [
            [12.0, 6 * L, -12.0, 6 * L],
            [6 * L, 4 * L * L, -6 * L, 2 * L * L],
            [-12.0, -6 * L, 12.0, -6 * L],
            [6 * L, 2 * L * L, -6 * L, 4 * L * L],
        ]
    )


def beam_mass(m_per_length: float, L: float) -> np.ndarray:
    """Consistent mass of one Euler-Bernoulli element, DOFs (w1, r1, w2, r2)."""
    return (m_per_length * L / 420.0) * np.array(
        [
            [156.0, 22 * L, 54.0, -13 * L],
            [22 * L, 4 * L * L, 13 * L, -3 * L * L],
            [54.0, 13 * L, 156.0, -22 * L],
            [-13 * L, -3 * L * L, -22 * L, 4 * L * L],
        ]
    )


def hermite(xi: float, L: float) -> np.ndarray:
    """Hermite shape functions for w at local coordinate ``xi`` in [0, 1] of an element of length L."""
    return np.array(
        [
            1 - 3 * xi**2 + 2 * xi**3,
            L * (xi - 2 * xi**2 + xi**3),
            3 * xi**2 - 2 * xi**3,
            L * (-(xi**2) + xi**3),
        ]
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

    def element_at(self, x: float) -> int:
        e = int(np.searchsorted(self.node_x, x, side="right")) - 1
        return min(max(e, 0), self.n_elements - 1)


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
    g = spec.girder
    if g is None:
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
    damping_factors: list[list[int]] = []
    for i, p in enumerate(params):
        dmp: list[int] = []
        for loc in p.targets:
            if loc[:2] == ("girder", "section"):
                spans = [loc[2]] if len(loc) == 4 else list(range(n_spans))
                owner = ei_owner if loc[-1] in ("E", "I") else ma_owner
                for k in spans:
                    owner[k] = i
            elif loc[:2] == ("girder", "bearings"):
                (kv_owner if loc[-1] == "k_vertical" else kr_owner)[loc[2]] = i
            elif loc[:2] == ("damping", "ratios"):
                dmp.append(loc[2])
        damping_factors.append(dmp)

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
    for i, x in enumerate(mesh.node_x):
        labels += [f"w@{x:.6g}", f"r@{x:.6g}"]

    sensor_dofs: dict[str, int] = {}
    sensor_rows: dict[str, np.ndarray] = {}
    for s in spec.sensors:
        sensor_rows[s.id] = deck_observation(mesh.node_x, [s.x])[0]
        node = mesh.node_at(s.x, tol)
        if node is not None:
            sensor_dofs[s.id] = 2 * node
            sensor_rows[s.id] = np.zeros(n_dof)
            sensor_rows[s.id][2 * node] = 1.0

    return assemble_model(spec, params, K0, M0, K_terms, M_terms, labels, sensor_dofs,
                          damping_factors, base_influence=None, sensor_rows=sensor_rows,
                          kind="girder", direction="vertical", node_x=mesh.node_x.copy())


def deck_observation(node_x: np.ndarray, xs) -> np.ndarray:
    """Rows (len(xs), 2 * n_nodes) giving the vertical displacement at each ``x`` along the deck."""
    node_x = np.asarray(node_x, dtype=float)
    n_dof = 2 * len(node_x)
    out = np.zeros((len(xs), n_dof))
    for r, x in enumerate(xs):
        if x < node_x[0] - 1e-9 or x > node_x[-1] + 1e-9:
            raise ValueError(f"x = {x} is outside the deck [{node_x[0]}, {node_x[-1]}]")
        e = int(np.clip(np.searchsorted(node_x, x, side="right") - 1, 0, len(node_x) - 2))
        Le = node_x[e + 1] - node_x[e]
        xi = float(np.clip((x - node_x[e]) / Le, 0.0, 1.0))
        out[r, 2 * e : 2 * e + 4] = hermite(xi, Le)
    return out
