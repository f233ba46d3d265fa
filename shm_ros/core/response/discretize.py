"""Exact discretisation of a continuous state space for inputs linear between samples.

With u piecewise linear (first-order hold: the samples joined by straight lines), one step of
dz/dt = A z + B u is exactly

    z[k+1] = Phi z[k] + G1 u[k] + G2 (u[k+1] - u[k])

with Phi = e^{Ah}, G1 = int_0^h e^{A s} ds B, G2 = int_0^h e^{A (h - s)} B s/h ds. All three are
blocks of one matrix exponential: expm(h [[A, B, 0], [0, 0, I/h], [0, 0, 0]]).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from .statespace import StateSpace


@dataclass
class DiscreteSystem:
    """One exact step of length ``dt`` (see module doc); outputs y[k] = C z[k] + D u[k]."""

    Phi: np.ndarray
    G1: np.ndarray
    G2: np.ndarray
    C: np.ndarray
    D: np.ndarray
    dt: float

    @property
    def n_states(self) -> int:
        return int(self.Phi.shape[0])


def discretize_foh(ss: StateSpace, dt: float) -> DiscreteSystem:
    """The first-order-hold step of ``ss`` for sample interval ``dt`` (s)."""
    Phi, G1, G2 = discretize_foh_batch(ss.A[None], ss.B[None], dt)
    return DiscreteSystem(Phi[0], G1[0], G2[0], ss.C, ss.D, float(dt))


def discretize_foh_batch(A: np.ndarray, B: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``Phi, G1, G2`` (K, n, n), (K, n, m), (K, n, m) of the stacked systems ``A`` (K, n, n), ``B``
    (K, n, m) for the sample interval ``dt``: the matrix exponentials of :func:`discretize_foh`, taken
    together (the same numbers, without a call per system)."""
    if not dt > 0:
        raise ValueError(f"dt must be > 0, got {dt}")
    A, B = np.asarray(A, float), np.asarray(B, float)
    K, n, m = B.shape
    aug = np.zeros((K, n + 2 * m, n + 2 * m))
    aug[:, :n, :n] = A * dt
    aug[:, :n, n:n + m] = B * dt
    aug[:, n:n + m, n + m:] = np.eye(m)
    E = expm(aug) if K else aug
    return E[:, :n, :n], E[:, :n, n:n + m], E[:, :n, n + m:]
