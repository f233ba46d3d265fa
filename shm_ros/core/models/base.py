"""What every structural model offers: an affine parametrisation and its modal solution.

Each updatable parameter of a structure file is a multiplicative factor on nominal values, and every
model kind here is linear in those factors:

    K(theta) = K0 + sum_i theta_i * K_i        M(theta) = M0 + sum_j theta_j * M_j

(a parameter acts on K, on M, or on neither, e.g. a damping factor). Keeping that form explicit lets
the updating core evaluate many theta at once and lets IIRS reduction work on the same terms.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ModalSolution:
    """Lowest modes of a model: frequencies ascending, mass-normalised shapes as columns."""

    frequencies_hz: np.ndarray  # (n_modes,)
    shapes: np.ndarray  # (n_dof, n_modes), phi^T M phi = I


@dataclass
class AffineModel:
    """A structural model in affine form, with named DOFs and sensor locations.

    ``K_terms[i]`` / ``M_terms[i]`` belong to ``parameter_names[i]`` (zero matrices or None where the
    parameter does not act on that matrix). ``theta`` = 1 everywhere is the nominal model.
    """

    name: str
    parameter_names: list[str]
    K0: np.ndarray
    M0: np.ndarray
    K_terms: list[np.ndarray | None]
    M_terms: list[np.ndarray | None]
    dof_labels: list[str]
    sensor_dofs: dict[str, int] = field(default_factory=dict)  # sensor id -> DOF index
    input_dof: int | None = None  # DOF of the measured input sensor, if any (base = None)
    damping_ratios: tuple[float, ...] = (0.02, 0.02)
    damping_kind: str = "rayleigh"  # "rayleigh" | "modal"
    # Influence vector of a base (ground) acceleration on the DOFs, for buildings under earthquakes.
    base_influence: np.ndarray | None = None

    @property
    def n_dof(self) -> int:
        return int(self.K0.shape[0])

    @property
    def n_parameters(self) -> int:
        return len(self.parameter_names)

    def nominal_theta(self) -> np.ndarray:
        return np.ones(self.n_parameters)

    def stiffness(self, theta: np.ndarray) -> np.ndarray:
        K = self.K0.copy()
        for t, Ki in zip(theta, self.K_terms):
            if Ki is not None:
                K += t * Ki
        return K

    def mass(self, theta: np.ndarray) -> np.ndarray:
        M = self.M0.copy()
        for t, Mi in zip(theta, self.M_terms):
            if Mi is not None:
                M += t * Mi
        return M

    def modes(self, theta: np.ndarray | None = None, n_modes: int = 6) -> ModalSolution:
        """Lowest ``n_modes`` by the generalised symmetric eigensolver (selected eigenvalues only)."""
        from scipy.linalg import eigh

        theta = self.nominal_theta() if theta is None else np.asarray(theta, dtype=float)
        n = min(n_modes, self.n_dof)
        w2, phi = eigh(self.stiffness(theta), self.mass(theta), subset_by_index=(0, n - 1))
        return ModalSolution(np.sqrt(np.clip(w2, 0.0, None)) / (2 * np.pi), phi)

    def sensor_matrix(self, sensor_ids: list[str]) -> np.ndarray:
        """Selection matrix (n_sensors, n_dof) that reads the sensors' DOFs."""
        S = np.zeros((len(sensor_ids), self.n_dof))
        for r, sid in enumerate(sensor_ids):
            S[r, self.sensor_dofs[sid]] = 1.0
        return S
