"""A building with rigid floor diaphragms (x, y, torsion per floor) on story springs per column line.

Every floor is a rigid diaphragm (``ops.rigidDiaphragm``) whose master node sits at the floor's
centre of mass, offset from the plan centre by 2-6 % of the plan width in x and y
the column lines
are the diaphragm's slaves. Each story has one spring element per column line acting in x and y
(``zeroLength`` for a fixed base; ``twoNodeLink`` with stiff axial and bending directions on a
foundation, so that foundation rocking carries the floors rigidly). The lines' shares of the story
stiffness are unequal, so stiffness and mass eccentricity couple translation and torsion. The lines
stand at 0.32-0.43 of the plan width from its centre (stiff cores and frames inside the façade), which
puts the torsional frequency at 1.1-1.5 times the translational ones, as in most real buildings.
Story stiffnesses are chosen for a first frequency of 2-5 Hz.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

COLUMN_LINES = ((0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (0.5, 0.0), (0.5, 1.0))  # plan fractions


@dataclass
class Building:
    masses: np.ndarray            # (n,) floor masses, kg (floor 1 first)
    k_x: np.ndarray               # (n,) story stiffness in x (all lines together), N/m
    k_y: np.ndarray               # (n,) in y
    heights: np.ndarray           # (n,) story heights, m
    plan: tuple[float, float]     # plan dimensions Lx, Ly, m
    share_x: np.ndarray           # (lines,) share of each column line in the x stiffness
    share_y: np.ndarray
    cm_offset: tuple[float, float]  # centre of mass minus plan centre, m
    zeta: tuple[float, float]     # Rayleigh ratios met at the first two modes
    damper_c: np.ndarray          # (n,) linear viscous dampers per story and direction, N s/m
    sensor_xy: tuple[float, float]  # plan position of the floor accelerometers, m
    instrumented: list[int] = field(default_factory=list)  # floors with an accelerometer
    line_spread: float = 0.5      # column lines at plan fractions 0.5 +- spread (0.5: at the edges)

    @property
    def n(self) -> int:
        return int(self.masses.size)

    def lines_xy(self) -> list[tuple[float, float]]:
        lx, ly = self.plan
        a = 2.0 * self.line_spread
        return [((0.5 + a * (fx - 0.5)) * lx, (0.5 + a * (fy - 0.5)) * ly)
                for fx, fy in COLUMN_LINES[: self.share_x.size]]

    def cm_xy(self) -> tuple[float, float]:
        return self.plan[0] / 2 + self.cm_offset[0], self.plan[1] / 2 + self.cm_offset[1]

    def polar_inertia(self, m: float) -> float:
        lx, ly = self.plan
        return m * (lx**2 + ly**2) / 12.0

    def heights_above_base(self) -> np.ndarray:
        return np.cumsum(self.heights)


def shear_chain_factor(n: int) -> float:
    """(omega_1)^2 m / k of a uniform n-story shear chain: 4 sin^2(pi / (2 (2n + 1)))."""
    return 4.0 * np.sin(np.pi / (2 * (2 * n + 1))) ** 2


def draw_building(rng: np.random.Generator, n: int, f1_hz: float | None = None) -> Building:
    """A realistic building of ``n`` stories: first mode 2-5 Hz, damping 1-5 %, CM offset 2-6 %."""
    f1 = float(rng.uniform(2.0, 5.0)) if f1_hz is None else f1_hz
    lx, ly = float(rng.uniform(15.0, 30.0)), float(rng.uniform(12.0, 24.0))
    m_floor = 1000.0 * lx * ly * float(rng.uniform(0.8, 1.1))          # ~1 t/m^2 of floor
    masses = m_floor * rng.uniform(0.95, 1.05, n)
    masses[-1] *= 0.85                                                  # lighter roof
    k_uniform = float(np.mean(masses)) * (2 * np.pi * f1) ** 2 / shear_chain_factor(n)
    taper = np.linspace(1.0, 0.7, n) if n > 1 else np.ones(1)           # stiffer low stories
    k_x = k_uniform * taper / np.mean(taper) * rng.uniform(0.92, 1.08, n)
    k_y = k_x * float(rng.uniform(0.8, 1.25)) * rng.uniform(0.95, 1.05, n)
    n_lines = 6 if n > 3 else 4
    share_x = rng.uniform(0.7, 1.3, n_lines)
    share_y = rng.uniform(0.7, 1.3, n_lines)
    sign = rng.choice([-1.0, 1.0], 2)
    cm = (float(sign[0] * rng.uniform(0.02, 0.06) * lx), float(sign[1] * rng.uniform(0.02, 0.06) * ly))
    zeta = (float(rng.uniform(0.015, 0.04)), float(rng.uniform(0.015, 0.04)))
    damper_c = np.zeros(n)
    story = int(rng.integers(0, n))                                     # one damped story
    damper_c[story] = 2.0 * float(rng.uniform(0.01, 0.02)) * k_x[story] / (2 * np.pi * f1)
    instrumented = sorted({1, n, *rng.choice(np.arange(1, n + 1), size=min(n, 2), replace=False).tolist()})
    return Building(masses=masses, k_x=k_x, k_y=k_y, heights=rng.uniform(3.2, 4.2, n),
                    plan=(lx, ly), share_x=share_x / share_x.sum(), share_y=share_y / share_y.sum(),
                    cm_offset=cm, zeta=zeta, damper_c=damper_c,
                    sensor_xy=(float(rng.uniform(0.3, 0.7) * lx), float(rng.uniform(0.8, 0.95) * ly)),
                    instrumented=[int(f) for f in instrumented],
                    line_spread=float(rng.uniform(0.32, 0.43)))
