"""Amplitude-dependent stiffness: the structure softens as it vibrates harder (cracked concrete
opening, friction in joints and bearings slipping), equivalent-linear per window:
stiffness factor ``1 / (1 + a / a_ref)`` with ``a`` the window's RMS acceleration (or PGA)."""

from __future__ import annotations

import numpy as np

from ._common import amplitude
from .base import CANDIDATES, Candidate, Modification, ParamSpec


@CANDIDATES.register("amplitude_stiffness")
class AmplitudeStiffness(Candidate):
    vocabulary = "amplitude_dependent_stiffness"
    explanation = ("The stiffness drops when the structure shakes harder (cracks open, joints slip), so "
                   "frequencies are lower in busy or stormy windows than in quiet ones.")

    def params(self) -> list[ParamSpec]:
        # softening per unit amplitude 1 / a_ref: log-uniform over the amplitudes that matter
        # up to a_ref = 1/100 of the largest amplitude seen; uniform so that 0 (no softening) is inside
        _, a = amplitude(self.context)
        top = max(float(np.nanmax(a)) if a.size else 1.0, 1e-9)
        return [ParamSpec("softening_per_accel", 0.0, 1e2 / top, null=0.0, unit="s^2/m")]

    def modify(self, theta: np.ndarray) -> Modification:
        k = np.atleast_2d(np.asarray(theta, float))[:, 0]
        _, a = amplitude(self.context)
        return Modification(groups={self.group: 1.0 / (1.0 + k[:, None] * a[None, :])})

    def form(self, theta: np.ndarray) -> str:
        name, _ = amplitude(self.context)
        k = float(np.ravel(theta)[0])
        return f"{self.group} stiffness x 1 / (1 + a / {1.0 / max(k, 1e-12):.3g}), a = {name}"
