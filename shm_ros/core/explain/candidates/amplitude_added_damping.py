"""Amplitude-dependent damping added beside the story springs: dashpots whose coefficient grows with
the vibration amplitude (friction in joints, cracks rubbing, story by story), so a mode's added
damping grows with its frequency (stiffness-proportional), unlike :mod:`.amplitude_damping`, which
scales every mode's damping alike.

Time domain only (:mod:`shm_ros.core.explain.timedomain`): the first mode's damping at amplitude ``a`` is
``zeta_1 (1 + k a)`` (the same parameter as :mod:`.amplitude_damping`), mode ``j`` gaining
``k a zeta_1 omega_j / omega_1``; the added part is the ``_added_damping`` column of
:class:`shm_ros.core.explain.td_model.FactorModel`.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from ._common import amplitude
from .amplitude_damping import AmplitudeDamping
from .base import CANDIDATES, Modification


@CANDIDATES.register("amplitude_added_damping")
class AmplitudeAddedDamping(AmplitudeDamping):
    """The parameter and its prior are :class:`AmplitudeDamping`'s (the first mode's slope)."""

    explanation = ("Damping grows when the structure shakes harder, added story by story beside the "
                   "springs (friction in joints, cracks rubbing), so the higher modes gain the most.")
    default_groups: ClassVar[tuple[str, ...]] = ()  # needs the time-domain model (not a modal factor)
    factor_column: ClassVar[str] = "added_damping"
    # within events only: per event, the uniform factor of amplitude_damping stands for it (on the
    # series of the tests the two per-event forms differ by ~14 nats, within events by ~100)
    resolutions: ClassVar[tuple[str, ...]] = ("within_event",)

    def modify(self, theta: np.ndarray) -> Modification:
        k = np.atleast_2d(np.asarray(theta, float))[:, 0]
        _, a = amplitude(self.context)
        return Modification(groups={}, damping=np.ones((k.size, a.size)), added_damping=k[:, None] * a[None, :])

    def form(self, theta: np.ndarray) -> str:
        name, _ = amplitude(self.context)
        k = float(np.ravel(theta)[0])
        return (f"first-mode damping x (1 + a / {1.0 / max(k, 1e-12):.3g}), added in proportion to the "
                f"stiffness (mode j: x omega_j / omega_1), a = {name}")
