"""Damper stiffness: the damper braces of the file (group ``damper``) add stiffness the file leaves
out, and it changes with the temperature (viscoelastic dampers soften as they warm) or drops at a
time (a damper fails).

What modal data can identify is the *change* of the braces' stiffness: its constant part is absorbed
by the calibration of the story stiffnesses (the nominal parameters), so the parameters are changes,
in units of the braced story's calibrated stiffness (which holds the braces' constant part: a brace
of k_b on a story of k_s changing by dk_b reads dk_b / (k_s + k_b)): per degC at the campaign's
mean temperature with an exponential softening (a viscoelastic material's stiffness falls about
exponentially with the temperature, k(T) = k0 exp(-b (T - T_mean)), b of 0-0.15 /degC), or lost at
a window (locate's ``change_index``); without a hint, a constant brace stiffness. The group's factor
is additive: ``x - 1 = brace stiffness / reference``, the reference being
:data:`shm_ros.core.explain.groups.DAMPER_REFERENCE` of the story's stiffness.
"""

from __future__ import annotations

import numpy as np

from ..groups import DAMPER_REFERENCE
from ._common import after_change, change_time, hinted_time_span, hinted_window_look_elsewhere, temperatures
from .base import CANDIDATES, Candidate, Modification, ParamSpec


@CANDIDATES.register("damper_stiffness")
class DamperStiffness(Candidate):
    vocabulary = "damper_stiffness"
    explanation = ("The dampers also stiffen the building; their stiffness falls as they warm or when one "
                   "fails, which moves the frequencies of the modes that strain the braced stories.")
    default_groups = ("damper",)

    def _change(self) -> str:
        h = self.context.hints
        return "step" if "change_index" in h else "temperature" if h.get("covariate") == "temperature_c" else "none"

    def params(self) -> list[ParamSpec]:
        change = self._change()
        if change == "temperature":
            return [ParamSpec("brace_change_per_c", -0.05, 0.05, null=0.0, unit="story stiffness / degC"),
                    ParamSpec("softening_rate_per_c", 0.0, 0.15, unit="1/degC")]
        if change == "step":
            return [ParamSpec("brace_lost", -0.5, 1.0, null=0.0, unit="story stiffness")]
        return [ParamSpec("brace_stiffness", 0.0, 1.0, null=0.0, unit="story stiffness")]

    def modify(self, theta: np.ndarray) -> Modification:
        th = np.atleast_2d(np.asarray(theta, float))
        v = th[:, :1]
        W = len(self.context.times_s)
        change = self._change()
        if change == "temperature":
            t, _ = temperatures(self.context)
            dt = (t - float(np.mean(t)))[None, :]
            b = th[:, 1:2]
            # k(T) = k0 exp(-b dT): slope v = -k0 b at the mean temperature; b -> 0 is the line v dT
            small = np.abs(b) < 1e-9
            dk = v * np.where(small, dt, -np.expm1(-b * dt) / np.where(small, 1.0, b))
        elif change == "step":
            on = after_change(self.context)
            dk = -v * on[None, :]
        else:
            dk = v * np.ones((1, W))
        return Modification(groups={self.group: 1.0 + dk / DAMPER_REFERENCE})

    def form(self, theta: np.ndarray) -> str:
        v = float(np.ravel(theta)[0])
        change = self._change()
        if change == "temperature":
            b = float(np.ravel(theta)[1])
            return (f"damper braces' stiffness {100 * v:+.2f} % of the story stiffness per degC at the mean "
                    f"temperature, softening exp(-{b:.3f} dT)")
        if change == "step":
            return (f"damper braces lose {100 * v:.1f} % of the story stiffness from window "
                    f"{self.context.hints['change_index']}")
        return f"damper braces {100 * v:.1f} % of the story stiffness"

    def time(self, theta: np.ndarray) -> float | None:
        if self._change() == "step":
            return change_time(self.context)
        return None

    def time_span(self, theta: np.ndarray, intervals: dict[str, tuple[float, float]]) -> tuple[float, float] | None:
        return None if self.time(theta) is None else hinted_time_span(self.context)

    def look_elsewhere(self) -> float:
        """From the hinted window on: ln(full range / hinted range) (:func:`._common.hinted_window_look_elsewhere`)."""
        return hinted_window_look_elsewhere(self.context) if self._change() == "step" else 0.0
