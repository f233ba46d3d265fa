"""A step in stiffness at a moment (damage, repair): x_w = 1 before t0, 1 + size from t0 on.

t0 is a grid parameter over the whole campaign (uniform between the 2nd and the second-to-last window:
a step at either end cannot be told from an offset), whatever locate hints: its change point is read
off the misfit with the other effects only roughly accounted for (a mild temperature dependence or a
freezing knee put a loss's hint 11-15 windows late), and with a misfit that drifts the step's gain
peaks at its own window alone, so a prior narrowed around the hint left the loss out. The fit's scan
of t0 at sizes spread over the prior finds that peak (:func:`shm_ros.core.explain.fit.find_map`), and
the full prior's evidence needs no look-elsewhere correction. ``size`` (null 0) is the relative change
of the group's stiffness, -60 % .. +40 %.
"""

from __future__ import annotations

import numpy as np

from .base import CANDIDATES, Candidate, Modification, ParamSpec


@CANDIDATES.register("step")
class Step(Candidate):
    vocabulary = "stiffness_change_at_time"
    explanation = ("The stiffness changed at a moment and stayed changed: damage (a drop) or a repair "
                   "or retrofit (a rise).")
    default_groups = ("EI", "EI:*")

    def params(self) -> list[ParamSpec]:
        t = np.asarray(self.context.times_s, dtype=float)
        lo, hi = (float(t[1]), float(t[-2])) if t.size > 3 else (0.0, 1.0)
        return [ParamSpec("size", -0.6, 0.4, null=0.0),
                ParamSpec("t0_s", lo, max(hi, lo + 1.0), unit="s", grid=True, moment=True)]

    def modify(self, theta: np.ndarray) -> Modification:
        th = np.atleast_2d(theta)
        t = np.asarray(self.context.times_s, dtype=float)
        on = t[None] >= th[:, 1:2]
        return Modification({self.group: np.where(on, 1.0 + th[:, 0:1], 1.0)})

    def form(self, theta: np.ndarray) -> str:
        return f"step of {100 * float(theta[0]):+.1f} % in stiffness at t0 = {float(theta[1]) / 3600:.1f} h"

    def time(self, theta: np.ndarray) -> float | None:
        return float(theta[1])
