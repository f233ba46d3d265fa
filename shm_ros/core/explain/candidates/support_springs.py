"""Support flexibility: the bearings' springs (girder, group ``bearings``) or the foundation's soil
(building, group ``foundation``) are softer than the file says, and their stiffness may change.

Parameters: when locate hints at a change, the change alone: a stiffening below a knee temperature
(frozen ground, hinted by ``covariate = temperature_c``) or a step from a window on
(scour, settlement: ``change_index``), relative to the calibrated supports (a free constant level
beside it trades off against the change: frequencies hardly depend on stiff supports, so a stiffer
level would need a larger step). Without a hint, the log of a constant stiffness factor.

The frost knee is a parameter (a grid over the measured temperatures' 5-95 % range, as the
temperature knee's): the ground freezes below about 0 degC of its own temperature, which the air
temperature reaches earlier or later, and locate's hinted knee is only as good as its search.
"""

from __future__ import annotations

import numpy as np

from ._common import after_change, change_time, hinted_time_span, hinted_window_look_elsewhere, temperatures
from .base import CANDIDATES, Candidate, Modification, ParamSpec


@CANDIDATES.register("support_springs")
class SupportSprings(Candidate):
    vocabulary = "support_flexibility"
    explanation = ("The supports give way more than the model assumes (soil under the bearings or the "
                   "foundation); when the soil freezes, is scoured or settles, the stiffness changes too.")
    default_groups = ("bearings",)

    def _change(self) -> str:
        h = self.context.hints
        if "change_index" in h:
            return "step"
        if h.get("covariate") == "temperature_c":  # the knee is fitted: a hinted one is not needed
            return "frost"
        return "none"

    def params(self) -> list[ParamSpec]:
        change = self._change()
        if change == "step":
            return [ParamSpec("ln_step", float(np.log(0.1)), float(np.log(3.0)), null=0.0)]
        if change == "frost":
            t, _ = temperatures(self.context)
            lo, hi = (np.quantile(t, [0.05, 0.95]) if t.size else (-1.0, 1.0))
            return [ParamSpec("frost_per_c", 0.0, 1.0, null=0.0, unit="1/degC"),
                    ParamSpec("knee_c", float(lo), float(max(hi, lo + 0.5)), unit="degC", grid=True)]
        return [ParamSpec("ln_stiffness_factor", float(np.log(0.2)), float(np.log(5.0)), null=0.0)]

    def modify(self, theta: np.ndarray) -> Modification:
        th = np.atleast_2d(np.asarray(theta, float))
        W = len(self.context.times_s)
        change = self._change()
        base = (np.ones((th.shape[0], W)) if change != "none"
                else np.exp(th[:, -1])[:, None] * np.ones((1, W)))
        if change == "step":
            on = after_change(self.context)
            base = base * np.exp(th[:, 0][:, None] * on[None, :])
        elif change == "frost":
            t, _ = temperatures(self.context)
            below = np.maximum(th[:, 1:2] - t[None, :], 0.0)
            base = base * (1.0 + th[:, 0:1] * below)
        return Modification(groups={self.group: base})

    def form(self, theta: np.ndarray) -> str:
        th = np.ravel(theta)
        change = self._change()
        if change == "step":
            return f"{self.group} stiffness x{np.exp(th[0]):.2f} from window {self.context.hints['change_index']}"
        if change == "frost":
            return f"{self.group} stiffness +{100 * th[0]:.1f} %/degC below {th[1]:.1f} degC (frozen ground)"
        return f"{self.group} stiffness x{np.exp(th[-1]):.2f}"

    def time(self, theta: np.ndarray) -> float | None:
        if self._change() == "step":
            return change_time(self.context)
        return None

    def time_span(self, theta: np.ndarray, intervals: dict[str, tuple[float, float]]) -> tuple[float, float] | None:
        return None if self.time(theta) is None else hinted_time_span(self.context)

    def look_elsewhere(self) -> float:
        """From the hinted window on: ln(full range / hinted range) (:func:`._common.hinted_window_look_elsewhere`)."""
        return hinted_window_look_elsewhere(self.context) if self._change() == "step" else 0.0
