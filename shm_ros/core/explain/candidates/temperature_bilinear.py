"""Stiffness bilinear in the air temperature (a knee): x_w = 1 + alpha (T - T_ref) + beta min(T - knee, 0).

Below the knee the slope is alpha + beta: a freezing deck surface or locking bearings stiffen the
structure much faster once the temperature falls below about 0 degC. The knee's prior is the
measured temperature range (5-95 % quantiles: a knee outside the data cannot be seen); it is a
grid parameter (the likelihood has a kink in it). beta is the key parameter (null 0).
"""

from __future__ import annotations

import numpy as np

from ._common import temperatures
from .base import CANDIDATES, Candidate, Modification, ParamSpec
from .temperature_linear import X_MIN


@CANDIDATES.register("temperature_bilinear")
class TemperatureBilinear(Candidate):
    vocabulary = "temperature_dependent_stiffness"
    explanation = ("The stiffness follows the temperature with a knee: below it (e.g. when the deck "
                   "surface or the bearings freeze) the structure stiffens much faster.")

    def params(self) -> list[ParamSpec]:
        t, _ = temperatures(self.context)
        lo, hi = (np.quantile(t, [0.05, 0.95]) if t.size else (-1.0, 1.0))
        return [ParamSpec("below_per_c", -0.15, 0.15, null=0.0, unit="1/degC"),
                ParamSpec("knee_c", float(lo), float(max(hi, lo + 0.5)), unit="degC", grid=True),
                ParamSpec("alpha_per_c", -0.03, 0.03, null=0.0, unit="1/degC")]

    def modify(self, theta: np.ndarray) -> Modification:
        t, ref = temperatures(self.context)
        th = np.atleast_2d(theta)
        beta, knee, alpha = th[:, 0:1], th[:, 1:2], th[:, 2:3]
        x = 1.0 + alpha * (t[None] - ref) + beta * np.minimum(t[None] - knee, 0.0)
        return Modification({self.group: np.maximum(x, X_MIN)})

    def form(self, theta: np.ndarray) -> str:
        beta, knee, alpha = (float(v) for v in theta)
        return (f"bilinear, knee at {knee:.1f} degC, {100 * alpha:+.2f} %/degC of stiffness above, "
                f"{100 * (alpha + beta):+.2f} %/degC below")
