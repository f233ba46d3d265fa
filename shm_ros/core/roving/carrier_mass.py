"""A mode's frequency without the robot, from how it falls with the robot's position.

The robot that carries the roving sensors stands where they measure, and its mass ``m`` lowers
every mode it stands on: to first order ``f_k = f_0 (1 - m phi(x_k)^2 / (2 M))`` with ``phi`` the mode
at the robot's point ``x_k`` in setup ``k`` and ``M`` the modal mass. The merged shape gives
``phi(x_k)`` (up to scale), so over the setups that found the mode the frequency is a straight line
in ``phi(x_k)^2``: a least-squares fit ``f_k = f_0 - b phi(x_k)^2`` gives the unloaded ``f_0`` at
``phi = 0`` without knowing ``m`` or ``M``. A mass only lowers a frequency, so a slope ``b <= 0`` (the
scatter, not the robot) keeps the setups' mean; so do fewer than ``min_setups`` setups, squared
components spanning less than ``min_span`` (of the largest, 1) and, if asked, a slope below
``min_t`` standard errors. The default asks nothing more than a fall: on the girder-roving scenario
at full size (12 setups of 120 s) a two-standard-error gate left mode 2 of seed 0 at the setups'
mean, -0.50 % (-0.16 % with the fit), while the setups' frequencies are biased low by the robot.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["unloaded_frequency"]


def unloaded_frequency(frequencies_hz: Sequence[float], phi2: Sequence[float], min_setups: int = 4,
                       min_span: float = 0.25, min_t: float = 0.0) -> tuple[float, float] | None:
    """``(f_0, b)`` of the fit in the module doc (``phi2`` on the merged shape's scale, max
    |component| = 1), or None when the data cannot carry it or the slope is not a fall."""
    f = np.asarray(frequencies_hz, dtype=float)
    x = np.asarray(phi2, dtype=float)
    ok = np.isfinite(f) & np.isfinite(x)
    f, x = f[ok], x[ok]
    if f.size < min_setups or np.ptp(x) < min_span:
        return None
    design = np.column_stack([np.ones_like(x), -x])
    (f0, b), *_ = np.linalg.lstsq(design, f, rcond=None)
    resid = f - design @ np.array([f0, b])
    s2 = float(resid @ resid) / (f.size - 2)
    se_b = np.sqrt(s2 * np.linalg.inv(design.T @ design)[1, 1])
    if b <= 0 or b <= min_t * se_b:
        return None
    return float(f0), float(b)
