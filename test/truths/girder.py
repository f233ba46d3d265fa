"""A three-span continuous girder (2-D, OpenSees ``elasticBeamColumn``) on bearings (``zeroLength``).

Vertical bending only: masses are lumped vertically at the nodes (no axial inertia, so no axial
modes among the first bending modes), one bearing holds the girder horizontally. Each bearing is a
vertical spring and a rotational spring (the rotational one is where stick-slip acts).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .opensees import eigen_hz, fresh, ops


@dataclass
class Girder:
    spans: tuple[float, float, float]
    E: float
    I: float          # noqa: E741 - the second moment of area
    A: float
    rho: float
    k_vertical: np.ndarray   # (4,) N/m
    k_rotation: np.ndarray   # (4,) N m/rad (0: free to rotate)
    sensor_x: list[float]
    elements_per_span: int = 10

    @property
    def bearing_x(self) -> list[float]:
        return [0.0, *np.cumsum(self.spans).tolist()]

    def node_x(self) -> np.ndarray:
        xs = [0.0]
        for x0, span in zip(self.bearing_x[:-1], self.spans, strict=True):
            xs += (x0 + span * np.arange(1, self.elements_per_span + 1) / self.elements_per_span).tolist()
        return np.unique(np.round(np.concatenate([xs, self.sensor_x]), 6))


def draw_girder(rng: np.random.Generator) -> Girder:
    """A concrete box girder, main span 35-50 m, side spans 0.55-0.75 of it
    first mode ~2-4 Hz."""
    main = float(rng.uniform(35.0, 50.0))
    side = main * float(rng.uniform(0.55, 0.75))
    spans = (side, main, side)
    k_v = float(rng.uniform(3e9, 8e9))
    sensors = sorted({round(side / 2, 2), round(side + main / 4, 2), round(side + main / 2, 2),
                      round(side + 3 * main / 4, 2), round(1.5 * side + main, 2)})
    return Girder(spans=spans, E=float(rng.uniform(3.2e10, 3.8e10)), I=float(rng.uniform(1.5, 3.0)),
                  A=float(rng.uniform(4.5, 7.0)), rho=2500.0, k_vertical=np.full(4, k_v),
                  k_rotation=np.zeros(4), sensor_x=sensors)


def girder_modes(g: Girder, e_factor: float, k_vertical: np.ndarray, k_rotation: np.ndarray,
                 n_modes: int) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies (n_modes,) and vertical shapes at the sensors (n_sensors, n_modes)."""
    fresh(2, 3)
    xs = g.node_x()
    ops.geomTransf("Linear", 1)
    m_per_m = g.rho * g.A
    for i, x in enumerate(xs):
        ops.node(i + 1, float(x), 0.0)
    lengths = np.diff(xs)
    for i in range(xs.size):
        trib = 0.5 * ((lengths[i - 1] if i > 0 else 0.0) + (lengths[i] if i < lengths.size else 0.0))
        ops.mass(i + 1, 0.0, m_per_m * trib, 0.0)
    for i in range(xs.size - 1):
        ops.element("elasticBeamColumn", i + 1, i + 1, i + 2, g.A, g.E * e_factor, g.I, 1)
    tag = 0
    for j, xb in enumerate(g.bearing_x):
        node = int(np.argmin(np.abs(xs - xb))) + 1
        ground = 10000 + j
        ops.node(ground, float(xs[node - 1]), 0.0)
        ops.fix(ground, 1, 1, 1)
        tag += 1
        ops.uniaxialMaterial("Elastic", tag, float(k_vertical[j]))
        mats, dirs = [tag], [2]
        if k_rotation[j] > 0:
            tag += 1
            ops.uniaxialMaterial("Elastic", tag, float(k_rotation[j]))
            mats.append(tag)
            dirs.append(3)
        if j == 0:  # the fixed bearing holds the girder horizontally
            tag += 1
            ops.uniaxialMaterial("Elastic", tag, 1e12)
            mats.append(tag)
            dirs.append(1)
        ops.element("zeroLength", 1000 + j, ground, node, "-mat", *mats, "-dir", *dirs)
    f = eigen_hz(n_modes, "-genBandArpack")
    nodes = [int(np.argmin(np.abs(xs - x))) + 1 for x in g.sensor_x]
    phi = np.array([[ops.nodeEigenvector(nd, k + 1, 2) for k in range(n_modes)] for nd in nodes])
    ops.wipe()
    return f, phi
