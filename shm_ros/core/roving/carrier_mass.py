"""A mode's frequency without the robot, from how it falls with the robot's position.

The robot that carries the roving sensors stands where they measure, and its mass ``m`` lowers
every mode it stands on: to first order ``f_k = f_0 (1 - m phi(x_k)^2 / (2 M))`` with ``phi`` the mode
at the robot's point ``x_k`` in setup ``k`` and ``M`` the modal mass on the same scale of ``phi``.

**One mass for the modes of interest** (:func:`carrier_mass`, :func:`shifted_median`). With ``M_j``
from the nominal model (:meth:`~shm_ros.core.roving.nominal.NominalAtPoints.unit_max_modal_mass`)
and ``u_jk = phi_j(x_k)^2 / M_j`` from the merged shape, the setups of all modes of interest fit one
mass: ``f_jk = f0_j - m (fbar_j u_jk / 2)`` by least squares (one intercept per mode, ``fbar_j`` the
setups' mean), clipped at 0 (a mass only lowers a frequency). Each mode's ``f0_j`` is then the median
of its setups' frequencies shifted back, ``f_jk (1 + m u_jk / 2)``: a 120-s setup's frequency error
is heavy-tailed (kurtosis 4-25 over the girder-roving scenario's setups), and the median of twelve
shifted setups kept mode 2 of that scenario within 0.5 % of its truth in 73 of 73 development seeds
at full size where the per-mode fit below failed 5 (docs/roving.md). The fit uses the lowest modes
only: the higher nominal modes' modal masses carry the model-form error and their setups pulled
the mass to a third of the robot's.

**Per mode, without the nominal model** (:func:`unloaded_frequency`; modes outside those of interest,
or no nominal model). Over the setups that found the mode the frequency is a straight line in
``phi(x_k)^2``: a least-squares fit ``f_k = f_0 - b phi(x_k)^2`` gives the unloaded ``f_0`` at ``phi = 0``
without knowing ``m`` or ``M``. A slope ``b <= 0`` (the scatter, not the robot) keeps the setups' mean;
so do fewer than ``min_setups`` setups, squared components spanning less than ``min_span`` (of the
largest, 1) and, if asked, a slope below ``min_t`` standard errors.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["unloaded_frequency", "carrier_mass", "shifted_median"]


def _finite(*arrays: ArrayLike) -> list[np.ndarray]:
    a = [np.asarray(x, dtype=float) for x in arrays]
    ok = np.logical_and.reduce([np.isfinite(x) for x in a])
    return [x[ok] for x in a]


def unloaded_frequency(frequencies_hz: ArrayLike, phi2: ArrayLike, min_setups: int = 4,
                       min_span: float = 0.25, min_t: float = 0.0) -> tuple[float, float] | None:
    """``(f_0, b)`` of the per-mode fit in the module doc (``phi2`` on the merged shape's scale, max
    |component| = 1), or None when the data cannot carry it or the slope is not a fall."""
    f, x = _finite(frequencies_hz, phi2)
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


def carrier_mass(frequencies_hz: Sequence[ArrayLike], u: Sequence[ArrayLike],
                 min_setups: int = 4) -> float | None:
    """The robot's mass (kg) from every mode's setups (module doc): ``frequencies_hz[j]`` and
    ``u[j]`` (squared component at the robot's point over the modal mass, 1/kg) per setup of mode
    ``j``. None when no mode has ``min_setups`` setups or the squared components do not vary."""
    modes = [m for m in (_finite(f, x) for f, x in zip(frequencies_hz, u, strict=True)) if m[0].size >= min_setups]
    if not modes:
        return None
    n = sum(f.size for f, _ in modes)
    design = np.zeros((n, len(modes) + 1))
    rhs = np.zeros(n)
    row = 0
    for j, (f, x) in enumerate(modes):
        design[row:row + f.size, j] = 1.0
        design[row:row + f.size, -1] = -f.mean() * x / 2
        rhs[row:row + f.size] = f
        row += f.size
    if np.ptp(design[:, -1]) == 0:
        return None
    sol, *_ = np.linalg.lstsq(design, rhs, rcond=None)
    return max(float(sol[-1]), 0.0)


def shifted_median(frequencies_hz: ArrayLike, u: ArrayLike, mass_kg: float) -> float:
    """The median of the setups' frequencies shifted to no robot, ``f_k (1 + m u_k / 2)``."""
    f, x = _finite(frequencies_hz, u)
    if f.size == 0:
        return float("nan")
    return float(np.median(f * (1 + mass_kg * x / 2)))
