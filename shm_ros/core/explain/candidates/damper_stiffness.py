"""Damper stiffness: the damper braces of the file (group ``damper``) add stiffness the file leaves
out, and it changes with the temperature (viscoelastic dampers soften as they warm) or drops at a
time (a damper fails). The group's factor is additive (x - 1 = brace stiffness / reference).

Parameters: the braces' stiffness relative to the reference, and, by locate's hints, its change per
degC (``covariate = temperature_c``) or its factor after a window (``change_index``).
"""

from __future__ import annotations

import numpy as np

from ._common import covariate
from .base import CANDIDATES, Candidate, Modification, ParamSpec


@CANDIDATES.register("damper_stiffness")
class DamperStiffness(Candidate):
    vocabulary = "damper_stiffness"
    explanation = ("The dampers also stiffen the building; their stiffness falls as they warm or when one "
                   "fails, which moves the frequencies of the modes that strain the braced stories.")

    def _change(self) -> str:
        h = self.context.hints
        return "step" if "change_index" in h else "temperature" if h.get("covariate") == "temperature_c" else "none"

    def params(self) -> list[ParamSpec]:
        out = [ParamSpec("brace_stiffness", 0.0, 3.0, null=None, unit="x reference")]
        change = self._change()
        if change == "temperature":
            out.insert(0, ParamSpec("per_c", -0.1, 0.1, null=0.0, unit="1/degC"))
        elif change == "step":
            out.insert(0, ParamSpec("after_factor", 0.0, 2.0, null=1.0))
        return out

    def modify(self, theta: np.ndarray) -> Modification:
        th = np.atleast_2d(np.asarray(theta, float))
        W = len(self.context.times_s)
        k = th[:, -1][:, None] * np.ones((1, W))
        change = self._change()
        if change == "temperature":
            t = covariate(self.context, "temperature_c")
            k = k * np.exp(th[:, 0][:, None] * (t - float(np.mean(t)))[None, :])
        elif change == "step":
            on = (np.arange(W) >= int(self.context.hints["change_index"])).astype(float)
            k = k * (1.0 + (th[:, 0][:, None] - 1.0) * on[None, :])
        return Modification(groups={self.group: 1.0 + k})

    def form(self, theta: np.ndarray) -> str:
        th = np.ravel(theta)
        s = f"damper braces {th[-1]:.2f} x reference stiffness"
        change = self._change()
        if change == "temperature":
            s += f", {100 * th[0]:+.1f} %/degC"
        elif change == "step":
            s += f", x{th[0]:.2f} from window {self.context.hints['change_index']}"
        return s

    def key_parameter(self) -> str:
        return self.params()[0].name

    def time(self, theta: np.ndarray) -> float | None:
        if self._change() == "step":
            return float(self.context.times_s[int(self.context.hints["change_index"])])
        return None
