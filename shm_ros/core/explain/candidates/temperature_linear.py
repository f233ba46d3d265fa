"""Stiffness linear in the air temperature: x_w = 1 + alpha (T_w - T_ref).

T_ref is the median measured temperature (the baseline's calibration sees the average state, so
the candidate moves frequencies about it); a window without a temperature takes one interpolated
from its neighbours (:func:`._common.temperatures`). The prior
of alpha (+-3 %/degC of stiffness) covers asphalt and elastomer-bearing effects on girders, whose
frequencies move by up to about 1 %/degC.
"""

from __future__ import annotations

import numpy as np

from ._common import temperatures
from .base import CANDIDATES, Candidate, Modification, ParamSpec

X_MIN = 0.05  # a stiffness factor below this is no longer a temperature effect


@CANDIDATES.register("temperature_linear")
class TemperatureLinear(Candidate):
    vocabulary = "temperature_dependent_stiffness"
    explanation = ("The stiffness of the structure changes with the air temperature (e.g. asphalt "
                   "surfacing, elastomeric bearings, or concrete moisture), so its frequencies follow "
                   "the temperature.")

    def params(self) -> list[ParamSpec]:
        return [ParamSpec("alpha_per_c", -0.03, 0.03, null=0.0, unit="1/degC")]

    def modify(self, theta: np.ndarray) -> Modification:
        t, ref = temperatures(self.context)
        a = np.atleast_2d(theta)[:, 0:1]
        return Modification({self.group: np.maximum(1.0 + a * (t[None] - ref), X_MIN)})

    def form(self, theta: np.ndarray) -> str:
        _, ref = temperatures(self.context)
        return f"linear, {100 * float(theta[0]):+.2f} %/degC of stiffness about {ref:.1f} degC"
