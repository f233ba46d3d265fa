"""Amplitude-dependent damping: damping grows with the vibration amplitude (friction, cracks),
equivalent-linear per window: modal damping factor ``1 + a / a_ref``."""

from __future__ import annotations

import numpy as np

from ._common import amplitude
from .base import CANDIDATES, Candidate, Modification, ParamSpec


@CANDIDATES.register("amplitude_damping")
class AmplitudeDamping(Candidate):
    vocabulary = "amplitude_dependent_damping"
    explanation = ("Damping is larger when the structure shakes harder (friction in joints and bearings, "
                   "cracks rubbing), so busy or stormy windows show more damping than quiet ones.")

    def params(self) -> list[ParamSpec]:
        _, a = amplitude(self.context)
        top = max(float(np.nanmax(a)) if a.size else 1.0, 1e-9)
        return [ParamSpec("damping_per_accel", 0.0, 1e2 / top, null=0.0, unit="s^2/m")]

    def modify(self, theta: np.ndarray) -> Modification:
        k = np.atleast_2d(np.asarray(theta, float))[:, 0]
        _, a = amplitude(self.context)
        return Modification(groups={}, damping=1.0 + k[:, None] * a[None, :])

    def form(self, theta: np.ndarray) -> str:
        name, _ = amplitude(self.context)
        k = float(np.ravel(theta)[0])
        return f"modal damping x (1 + a / {1.0 / max(k, 1e-12):.3g}), a = {name}"
