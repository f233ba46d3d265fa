"""Euler-Bernoulli beam elements (vertical bending): element matrices and shape functions.

DOFs per node: vertical displacement ``w`` (m, up) and rotation ``r`` (rad). The element is the
classic two-node Hermite beam with consistent mass. Hand-written because no maintained Python
library offers an affine (per-parameter) assembly of a small beam model; the element matrices are
the textbook ones.
"""

from __future__ import annotations

import numpy as np


def beam_stiffness(EI: float, L: float) -> np.ndarray:
    """Bending stiffness of one Euler-Bernoulli element, DOFs (w1, r1, w2, r2)."""
    return (EI / L**3) * np.array(
        [
            [12.0, 6 * L, -12.0, 6 * L],
            [6 * L, 4 * L * L, -6 * L, 2 * L * L],
            [-12.0, -6 * L, 12.0, -6 * L],
            [6 * L, 2 * L * L, -6 * L, 4 * L * L],
        ]
    )


def beam_mass(m_per_length: float, L: float) -> np.ndarray:
    """Consistent mass of one Euler-Bernoulli element, DOFs (w1, r1, w2, r2)."""
    return (m_per_length * L / 420.0) * np.array(
        [
            [156.0, 22 * L, 54.0, -13 * L],
            [22 * L, 4 * L * L, 13 * L, -3 * L * L],
            [54.0, 13 * L, 156.0, -22 * L],
            [-13 * L, -3 * L * L, -22 * L, 4 * L * L],
        ]
    )


def hermite(xi: float, L: float) -> np.ndarray:
    """Hermite shape functions for w at local coordinate ``xi`` in [0, 1] of an element of length L."""
    return np.array(
        [
            1 - 3 * xi**2 + 2 * xi**3,
            L * (xi - 2 * xi**2 + xi**3),
            3 * xi**2 - 2 * xi**3,
            L * (-(xi**2) + xi**3),
        ]
    )


def deck_observation(node_x: np.ndarray, xs) -> np.ndarray:
    """Rows (len(xs), 2 * n_nodes) giving the vertical displacement at each ``x`` along the deck."""
    node_x = np.asarray(node_x, dtype=float)
    n_dof = 2 * len(node_x)
    out = np.zeros((len(xs), n_dof))
    for r, x in enumerate(xs):
        if x < node_x[0] - 1e-9 or x > node_x[-1] + 1e-9:
            raise ValueError(f"x = {x} is outside the deck [{node_x[0]}, {node_x[-1]}]")
        e = int(np.clip(np.searchsorted(node_x, x, side="right") - 1, 0, len(node_x) - 2))
        Le = node_x[e + 1] - node_x[e]
        xi = float(np.clip((x - node_x[e]) / Le, 0.0, 1.0))
        out[r, 2 * e : 2 * e + 4] = hermite(xi, Le)
    return out
