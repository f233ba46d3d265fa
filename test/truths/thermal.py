"""Stiffness against the structure's temperature: a smooth knee near freezing.

E(T)/E(T_ref) = 1 + a (T_ref - T) + (b - a) w softplus((T_k - T) / w): slope a (0.1-0.4 %/degC)
above the knee T_k (-1.5 to +1.5 degC), slope b (1.5-4 %/degC) well below it, a smooth transition of
width w (0.5-2 degC) between: stiffening of frozen joints, asphalt and pore water. Not bilinear.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ThermalLaw:
    slope_above: float = 0.002   # per degC
    slope_below: float = 0.025
    knee_c: float = 0.0
    width_c: float = 1.0
    t_ref_c: float = 10.0

    @classmethod
    def draw(cls, rng: np.random.Generator) -> ThermalLaw:
        return cls(slope_above=float(rng.uniform(0.001, 0.004)), slope_below=float(rng.uniform(0.015, 0.04)),
                   knee_c=float(rng.uniform(-1.5, 1.5)), width_c=float(rng.uniform(0.5, 2.0)))

    def factor(self, t_c: np.ndarray) -> np.ndarray:
        z = (self.knee_c - np.asarray(t_c, dtype=float)) / self.width_c
        softplus = np.logaddexp(0.0, z) - np.logaddexp(0.0, (self.knee_c - self.t_ref_c) / self.width_c)
        linear = self.slope_above * (self.t_ref_c - t_c)
        return 1.0 + linear + (self.slope_below - self.slope_above) * self.width_c * softplus
