"""The nominal model at a roving structure's sensors and points.

The rows that read the nominal modes at every fixed sensor and measurement point (advice and
placement use them), each mode's modal mass on the scale of a shape whose largest component over
given points is 1 (the robot's-mass correction of :mod:`~shm_ros.core.roving.carrier_mass` needs
it), and the one-to-one assignment of identified global modes to the nominal modes of interest: one
optimal assignment (:func:`scipy.optimize.linear_sum_assignment`) on ``(1 - MAC) + |f / f_n - 1|``
over the pairs within ``MAC >= min_mac`` and ``frequency_tol``. The MAC gate is looser than the
updating's (0.8): the nominal model's model-form error leaves a girder's third vertical mode at
a MAC of 0.71-0.87 against its truth in the girder-roving scenario.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

from shm_ros.core.modal import mac
from shm_ros.core.structure import StructureSpec

__all__ = ["NominalAtPoints"]

MIN_MAC = 0.6
FREQUENCY_TOL = 0.15


class NominalAtPoints:
    """The lowest ``n_modes`` nominal modes of ``spec`` at its sensors and measurement points."""

    def __init__(self, spec: StructureSpec, n_modes: int) -> None:
        model = spec.model_kind.build(spec)
        sol = model.modes(n_modes=n_modes)
        self.n_modes = n_modes
        self.frequencies_hz = np.asarray(sol.frequencies_hz, dtype=float)[:n_modes]
        shapes = np.asarray(sol.shapes)[:, :n_modes]
        mass = model.mass()
        self._modal_mass = np.einsum("ij,ik,kj->j", shapes, mass, shapes)
        at = {s.id: s.at for s in spec.sensors} | {p.id: p.at for p in spec.measurement_points}
        self.rows = {k: np.asarray(model.location_row(a)) @ shapes for k, a in at.items()
                     if model.location_row(a) is not None}

    def shapes(self, ids: Sequence[str]) -> np.ndarray:
        """Nominal shapes at ``ids`` (sensors or points), (len(ids), n_modes)."""
        return np.array([self.rows[i] for i in ids]).reshape(len(ids), self.n_modes)

    def unit_max_modal_mass(self, ids: Sequence[str]) -> np.ndarray:
        """Each mode's modal mass with its shape scaled to a largest |component| of 1 over ``ids``
        (those the model reads)."""
        peak = np.max(np.abs(self.shapes([i for i in ids if i in self.rows])), axis=0, initial=0.0)
        return self._modal_mass / np.where(peak > 0, peak, np.nan) ** 2

    def assign(self, frequencies_hz: Sequence[float], shapes: Sequence[dict[str, float]],
               min_mac: float = MIN_MAC, frequency_tol: float = FREQUENCY_TOL) -> dict[int, int]:
        """``{identified index: nominal index}``, one to one (module doc); ``shapes`` map ids to
        components (ids the model cannot read, and non-finite components, are left out)."""
        cost = np.full((self.n_modes, len(shapes)), np.inf)
        for c, (f, shape) in enumerate(zip(frequencies_hz, shapes, strict=True)):
            ids = [k for k, v in shape.items() if k in self.rows and np.isfinite(v)]
            if len(ids) < 2:
                continue
            m = mac(np.array([shape[k] for k in ids])[None, :], self.shapes(ids).T)
            df = np.abs(self.frequencies_hz / f - 1)
            ok = (m >= min_mac) & (df <= frequency_tol)
            cost[ok, c] = (1 - m[ok]) + df[ok]
        if not np.isfinite(cost).any():
            return {}
        rows, cols = linear_sum_assignment(np.where(np.isfinite(cost), cost, 1e6))
        return {int(c): int(r) for r, c in zip(rows, cols, strict=True) if np.isfinite(cost[r, c])}
