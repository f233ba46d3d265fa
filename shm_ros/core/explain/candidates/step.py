"""A step in stiffness at a moment (damage, repair): x_w = 1 before t0, 1 + size from t0 on.

t0 is a grid parameter over the campaign (uniform between the 2nd and the second-to-last window:
a step at either end cannot be told from an offset), or, when locate hints a change window (its
exact search keeps the other regressors, e.g. a temperature knee, that a step fitted alone would
partly imitate), over the windows within ``HINT_WINDOWS`` of it (as added mass and damper
candidates take the hinted window itself), with the look-elsewhere correction ln(full range / hinted
range) taken off its evidence gain, so that the hint does not buy evidence that locate's search over
every window spent; ``time`` reports it. ``size`` (null 0) is
the relative change of the group's stiffness, -60 % .. +40 %.
"""

from __future__ import annotations

import numpy as np

from .base import CANDIDATES, Candidate, Modification, ParamSpec

HINT_WINDOWS = 6  # the step time's prior around a hinted change window (locate's resolution)


@CANDIDATES.register("step")
class Step(Candidate):
    vocabulary = "stiffness_change_at_time"
    explanation = ("The stiffness changed at a moment and stayed changed: damage (a drop) or a repair "
                   "or retrofit (a rise).")
    default_groups = ("EI", "EI:*")

    def _range(self, hinted: bool) -> tuple[float, float]:
        t = np.asarray(self.context.times_s, dtype=float)
        lo, hi = (float(t[1]), float(t[-2])) if t.size > 3 else (0.0, 1.0)
        if hinted and "change_index" in self.context.hints and t.size > 3:
            i = int(self.context.hints["change_index"])
            a, b = self.context.hints.get("change_span", (i, i))  # a change inside held-out windows: their span
            lo = float(t[min(max(int(a) - HINT_WINDOWS, 1), t.size - 2)])
            hi = float(t[min(max(int(b) + HINT_WINDOWS, 1), t.size - 2)])
        return lo, max(hi, lo + 1.0)

    def params(self) -> list[ParamSpec]:
        lo, hi = self._range(True)
        return [ParamSpec("size", -0.6, 0.4, null=0.0), ParamSpec("t0_s", lo, hi, unit="s", grid=True, moment=True)]

    def look_elsewhere(self) -> float:
        (lo, hi), (a, b) = self._range(True), self._range(False)
        return float(np.log((b - a) / (hi - lo)))

    def modify(self, theta: np.ndarray) -> Modification:
        th = np.atleast_2d(theta)
        t = np.asarray(self.context.times_s, dtype=float)
        on = t[None] >= th[:, 1:2]
        return Modification({self.group: np.where(on, 1.0 + th[:, 0:1], 1.0)})

    def form(self, theta: np.ndarray) -> str:
        return f"step of {100 * float(theta[0]):+.1f} % in stiffness at t0 = {float(theta[1]) / 3600:.1f} h"

    def time(self, theta: np.ndarray) -> float | None:
        return float(theta[1])
