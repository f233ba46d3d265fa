"""What every structural model offers: an affine parametrisation and its modal solution.

Each updatable parameter of a structure file is a multiplicative factor on nominal values, and every
model kind here is linear in those factors:

    K(theta) = K0 + sum_i theta_i * K_i        M(theta) = M0 + sum_j theta_j * M_j

(a parameter acts on K, on M, or on neither, e.g. a damping factor). Keeping that form explicit lets
the updating core evaluate many theta at once and lets IIRS reduction work on the same terms.

Batched helpers (``stiffness_batch``, ``mass_batch``, ``modes_batch``) take ``thetas`` of shape
``(B, n_parameters)`` and return stacked ``(B, n, n)`` arrays, so likelihoods can evaluate thousands
of parameter vectors per call.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from shm_ros.core.models.beam import deck_observation
from shm_ros.core.models.damping import rayleigh_coefficients, rayleigh_ratios

if TYPE_CHECKING:  # annotations only: the structure module imports this package's registry
    from shm_ros.core.structure import InputSpec


@dataclass(frozen=True)
class Damper:
    """A discrete viscous damper between two DOFs (None: the ground), acting on their relative motion.

    Without ``k_maxwell`` a Kelvin-Voigt dashpot (force ``c`` x relative velocity, part of
    :meth:`AffineModel.damping`); with it a Maxwell element, a spring ``k_maxwell`` in series with
    the dashpot, whose force is a state of its own (``shm_ros.core.response``).
    """

    nodes: tuple[int | None, int | None]
    c: float  # N s/m
    k_maxwell: float | None = None  # N/m

    @property
    def maxwell(self) -> bool:
        return self.k_maxwell is not None

    def incidence(self, n_dof: int) -> np.ndarray:
        """Row b (n_dof,) with b @ u = extension of the element (the ground's motion not included)."""
        b = np.zeros(n_dof)
        i, j = self.nodes
        if i is not None:
            b[i] += 1.0
        if j is not None:
            b[j] -= 1.0
        return b


@dataclass
class ModalSolution:
    """Lowest modes of a model: frequencies ascending, mass-normalised shapes as columns."""

    frequencies_hz: np.ndarray  # (n_modes,)
    shapes: np.ndarray  # (n_dof, n_modes), phi^T M phi = I


@dataclass
class BatchModalSolution:
    """Lowest modes for a batch of parameter vectors."""

    frequencies_hz: np.ndarray  # (B, n_modes)
    shapes: np.ndarray  # (B, n_dof, n_modes), mass-normalised


@dataclass
class AffineModel:
    """A structural model in affine form, with named DOFs and sensor locations.

    ``K_terms[i]`` / ``M_terms[i]`` belong to ``parameter_names[i]`` (zero matrices or None where the
    parameter does not act on that matrix). ``theta`` = 1 everywhere is the nominal model.

    Sensors: ``sensor_rows[id]`` is the observation row (n_dof,) that reads a sensor from the DOF
    vector (a unit row for a sensor at a DOF, Hermite shape-function values for a girder sensor
    between nodes); ``sensor_dofs[id]`` is filled only for sensors that sit exactly on a DOF.
    A ground (base) sensor of a building has neither: it is the input, ``input_sensor``.
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
    sensor_rows: dict[str, np.ndarray] = field(default_factory=dict)  # sensor id -> (n_dof,)
    input_sensor: str | None = None  # id of the structure's input sensor, if any
    # damping_factors[i]: indices of damping_ratios that parameter i multiplies (empty: none)
    damping_factors: list[list[int]] = field(default_factory=list)
    kind: str = "matrices"  # name of the structure kind (shm_ros.core.models.registry)
    direction: str | None = None  # direction of motion the DOFs describe ("vertical", "x", "y")
    node_x: np.ndarray | None = None  # girder: node coordinates along the deck (m)
    # discrete dampers (shear building ``dampers``); Kelvin-Voigt ones are part of ``damping``
    dampers: list[Damper] = field(default_factory=list)
    # the structure's inputs that act in this model's direction (docs/interfaces.md section 2)
    inputs: list[InputSpec] = field(default_factory=list)
    story_heights: np.ndarray | None = None  # shear building: height of each story (m), when given
    ground_sensors: list[str] = field(default_factory=list)  # sensors on the ground (a building's floor 0)

    def __post_init__(self) -> None:
        if not self.damping_factors:
            self.damping_factors = [[] for _ in self.parameter_names]
        for sid, dof in self.sensor_dofs.items():
            if sid not in self.sensor_rows:
                row = np.zeros(self.n_dof)
                row[dof] = 1.0
                self.sensor_rows[sid] = row

    @property
    def n_dof(self) -> int:
        return int(self.K0.shape[0])

    @property
    def n_parameters(self) -> int:
        return len(self.parameter_names)

    def nominal_theta(self) -> np.ndarray:
        return np.ones(self.n_parameters)

    def theta_vector(self, values: dict[str, float] | None = None) -> np.ndarray:
        """Parameter vector from ``{name: value}`` (missing names stay at 1)."""
        theta = self.nominal_theta()
        for k, v in (values or {}).items():
            theta[self.parameter_names.index(k)] = float(v)
        return theta

    # -- matrices ------------------------------------------------------------------------------
    def stiffness(self, theta: np.ndarray | None = None) -> np.ndarray:
        theta = self.nominal_theta() if theta is None else theta
        K = self.K0.copy()
        for t, Ki in zip(theta, self.K_terms, strict=True):
            if Ki is not None:
                K += t * Ki
        return K

    def mass(self, theta: np.ndarray | None = None) -> np.ndarray:
        theta = self.nominal_theta() if theta is None else theta
        M = self.M0.copy()
        for t, Mi in zip(theta, self.M_terms, strict=True):
            if Mi is not None:
                M += t * Mi
        return M

    def _thetas(self, thetas: np.ndarray) -> np.ndarray:
        thetas = np.asarray(thetas, dtype=float)
        if thetas.ndim == 1:
            thetas = thetas[None, :]
        if thetas.shape[1] != self.n_parameters:
            raise ValueError(
                f"thetas must have {self.n_parameters} columns ({self.parameter_names}), got {thetas.shape}"
            )
        return thetas

    def stiffness_batch(self, thetas: np.ndarray) -> np.ndarray:
        """K(theta) for each row of ``thetas`` (B, n_parameters) -> (B, n, n)."""
        thetas = self._thetas(thetas)
        return _affine_batch(self.K0, self.K_terms, thetas)

    def mass_batch(self, thetas: np.ndarray) -> np.ndarray:
        """M(theta) for each row of ``thetas`` (B, n_parameters) -> (B, n, n)."""
        thetas = self._thetas(thetas)
        return _affine_batch(self.M0, self.M_terms, thetas)

    # -- modes ---------------------------------------------------------------------------------
    def modes(self, theta: np.ndarray | None = None, n_modes: int = 6) -> ModalSolution:
        """Lowest ``n_modes`` by the generalised symmetric eigensolver (selected eigenvalues only)."""
        from scipy.linalg import eigh

        theta = self.nominal_theta() if theta is None else np.asarray(theta, dtype=float)
        n = min(n_modes, self.n_dof)
        w2, phi = eigh(self.stiffness(theta), self.mass(theta), subset_by_index=(0, n - 1))
        return ModalSolution(np.sqrt(np.clip(w2, 0.0, None)) / (2 * np.pi), phi)

    def modes_batch(self, thetas: np.ndarray, n_modes: int = 6) -> BatchModalSolution:
        """Lowest ``n_modes`` of the full model for each row of ``thetas`` (batched numpy eigh)."""
        return generalized_modes_batch(self.stiffness_batch(thetas), self.mass_batch(thetas), n_modes)

    # -- damping -------------------------------------------------------------------------------
    def damping_ratios_at(self, theta: np.ndarray | None = None) -> np.ndarray:
        """The nominal damping ratios with the factors of damping parameters applied."""
        theta = self.nominal_theta() if theta is None else np.asarray(theta, dtype=float)
        r = np.asarray(self.damping_ratios, dtype=float).copy()
        for t, idx in zip(theta, self.damping_factors, strict=True):
            for i in idx:
                r[i] *= t
        return r

    def damping_ratios_batch(self, thetas: np.ndarray) -> np.ndarray:
        """:meth:`damping_ratios_at` for each row of ``thetas`` -> (B, n_ratios)."""
        thetas = self._thetas(thetas)
        z = np.tile(np.asarray(self.damping_ratios, dtype=float), (thetas.shape[0], 1))
        for i, idx in enumerate(self.damping_factors):
            for j in idx:
                z[:, j] *= thetas[:, i]
        return z

    def modal_damping_ratios(self, theta: np.ndarray | None = None, n_modes: int = 6) -> np.ndarray:
        """Damping ratio of each of the lowest ``n_modes`` modes under this model's damping."""
        theta = self.nominal_theta() if theta is None else np.asarray(theta, dtype=float)
        z = self.damping_ratios_at(theta)
        n = min(n_modes, self.n_dof)
        if self.damping_kind == "modal":
            return np.array([z[min(k, len(z) - 1)] for k in range(n)])
        w = 2 * np.pi * self.modes(theta, max(n, 2)).frequencies_hz
        a0, a1 = rayleigh_coefficients(w[0], w[1], z[0], z[1])
        return rayleigh_ratios(w, a0, a1)[:n]

    def modal_damping_ratios_batch(self, thetas: np.ndarray, frequencies_hz: np.ndarray) -> np.ndarray:
        """Damping ratios (B, k) of modes with ``frequencies_hz`` (B, k) - the model's lowest modes at
        each row of ``thetas``, e.g. from ``modes_batch`` or a reduction (Rayleigh damping is fixed by
        the first two columns)."""
        thetas = self._thetas(thetas)
        f = np.atleast_2d(np.asarray(frequencies_hz, dtype=float))
        z = self.damping_ratios_batch(thetas)
        k = f.shape[1]
        if self.damping_kind == "modal":
            cols = [min(c, z.shape[1] - 1) for c in range(k)]
            return z[:, cols]
        w = 2 * np.pi * f
        a0, a1 = rayleigh_coefficients(w[:, :1], w[:, 1:2], z[:, :1], z[:, 1:2])
        return rayleigh_ratios(w, a0, a1)

    def damping(self, theta: np.ndarray | None = None) -> np.ndarray:
        """Viscous damping matrix C(theta): the inherent damping plus the Kelvin-Voigt dampers.

        With dampers the damping is non-classical (the undamped modes do not diagonalise C); Maxwell
        dampers are not in C: their force is a state (``shm_ros.core.response``).
        """
        return self.inherent_damping(theta) + self.damper_damping()

    def damper_damping(self) -> np.ndarray:
        """The Kelvin-Voigt dampers' dashpots assembled on the DOFs (zero without dampers)."""
        C = np.zeros((self.n_dof, self.n_dof))
        for d in self.dampers:
            if not d.maxwell:
                b = d.incidence(self.n_dof)
                C += d.c * np.outer(b, b)
        return C

    def inherent_damping(self, theta: np.ndarray | None = None) -> np.ndarray:
        """Viscous damping matrix of the structure itself, without discrete dampers.

        ``rayleigh``: C = a0 M + a1 K with the ratios met exactly at the first two modes of the model
        at ``theta``. ``modal``: C = M Phi diag(2 zeta_k omega_k) Phi^T M over all modes (the last
        ratio repeats for modes beyond the list).
        """
        from scipy.linalg import eigh

        theta = self.nominal_theta() if theta is None else np.asarray(theta, dtype=float)
        K, M = self.stiffness(theta), self.mass(theta)
        z = self.damping_ratios_at(theta)
        if self.damping_kind == "modal":
            w2, phi = eigh(K, M)
            w = np.sqrt(np.clip(w2, 0.0, None))
            zeta = np.array([z[min(k, len(z) - 1)] for k in range(len(w))])
            Mphi = M @ phi
            return (Mphi * (2 * zeta * w)) @ Mphi.T
        w2 = eigh(K, M, eigvals_only=True, subset_by_index=(0, min(1, self.n_dof - 1)))
        w = np.sqrt(np.clip(w2, 0.0, None))
        if len(w) < 2:  # one DOF: mass-proportional damping gives the ratio exactly
            return 2 * z[0] * w[0] * M
        a0, a1 = rayleigh_coefficients(w[0], w[1], z[0], z[1])
        return a0 * M + a1 * K

    def inherent_damping_batch(self, thetas: np.ndarray) -> np.ndarray:
        """:meth:`inherent_damping` for each row of ``thetas`` -> (B, n, n) (batched eigensolutions)."""
        thetas = self._thetas(thetas)
        K, M = self.stiffness_batch(thetas), self.mass_batch(thetas)
        z = self.damping_ratios_batch(thetas)
        if self.damping_kind == "modal":
            sol = generalized_modes_batch(K, M, self.n_dof)
            w = 2 * np.pi * sol.frequencies_hz
            zeta = z[:, [min(k, z.shape[1] - 1) for k in range(w.shape[1])]]
            Mphi = M @ sol.shapes
            return (Mphi * (2 * zeta * w)[:, None, :]) @ np.swapaxes(Mphi, -1, -2)
        w = 2 * np.pi * generalized_modes_batch(K, M, 2).frequencies_hz
        if w.shape[1] < 2:  # one DOF: mass-proportional damping gives the ratio exactly
            return (2 * z[:, 0] * w[:, 0])[:, None, None] * M
        a0, a1 = rayleigh_coefficients(w[:, 0], w[:, 1], z[:, 0], z[:, 1])
        return np.asarray(a0)[:, None, None] * M + np.asarray(a1)[:, None, None] * K

    # -- sensors -------------------------------------------------------------------------------
    def sensor_matrix(self, sensor_ids: list[str]) -> np.ndarray:
        """Observation matrix (n_sensors, n_dof) that reads the sensors from the DOF vector.

        A selection matrix for sensors located at DOFs; rows of shape-function values for girder
        sensors between nodes. Raises KeyError naming a sensor the model cannot observe (e.g. the
        ground sensor of a building, which is the base input).
        """
        S = np.zeros((len(sensor_ids), self.n_dof))
        for r, sid in enumerate(sensor_ids):
            if sid in self.sensor_rows:
                S[r] = self.sensor_rows[sid]
            elif sid in self.sensor_dofs:
                S[r, self.sensor_dofs[sid]] = 1.0
            else:
                raise KeyError(
                    f"model {self.name!r} has no DOF for sensor {sid!r}"
                    + (" (it is the base input)" if sid == self.input_sensor else "")
                )
        return S

    def location_row(self, at: dict[str, Any]) -> np.ndarray | None:
        """Row (n_dof,) reading the displacement at a structure-file location (``{floor: k}``,
        ``{x: m}``, ``{dof: i|label}``); its transpose spreads a point force there. None: the ground
        (floor 0), which is not a DOF."""
        row = np.zeros(self.n_dof)
        if "dof" in at:
            d = at["dof"]
            idx = self.dof_labels.index(d) if isinstance(d, str) else int(d)
            row[idx] = 1.0
        elif "floor" in at:
            k = int(at["floor"])
            if k == 0:
                return None
            label = f"floor{k}.{self.direction}"
            if label not in self.dof_labels:
                raise KeyError(f"model {self.name!r} has no DOF {label!r}")
            row[self.dof_labels.index(label)] = 1.0
        elif "x" in at:
            row = self.deck_observation([float(at["x"])])[0]
        else:
            raise KeyError(f"model {self.name!r} cannot locate {at!r}")
        return row

    def deck_observation(self, xs) -> np.ndarray:
        """Girder only: rows (len(xs), n_dof) reading the vertical displacement at any deck ``x``."""
        if self.node_x is None:
            raise ValueError(f"model {self.name!r} is not a girder: it has no deck coordinates")
        return deck_observation(self.node_x, list(xs))

    def observed_sensors(self, sensor_ids: list[str] | None = None) -> list[str]:
        """Those of ``sensor_ids`` (default: all the model's) that the model observes, order kept."""
        return [s for s in (sensor_ids or list(self.sensor_rows)) if s in self.sensor_rows]

    def master_dofs(self, sensor_ids: list[str] | None = None) -> list[int]:
        """DOF indices of sensors located on DOFs (the masters of a reduction), sensor order kept.

        Raises KeyError for a sensor that does not sit on a DOF.
        """
        ids = [s for s in self.sensor_dofs] if sensor_ids is None else sensor_ids
        out = []
        for sid in ids:
            if sid not in self.sensor_dofs:
                raise KeyError(f"sensor {sid!r} of model {self.name!r} is not located on a DOF")
            out.append(self.sensor_dofs[sid])
        return out


def _affine_batch(X0: np.ndarray, terms: list[np.ndarray | None], thetas: np.ndarray) -> np.ndarray:
    """``X0 + sum_i theta_i X_i`` for each row of ``thetas``, term by term as :meth:`AffineModel.stiffness`
    adds them: each row's matrix is then the same bit for bit whatever the batch (a single matrix
    product over the batch rounds differently with the batch's size)."""
    X = np.broadcast_to(X0, (thetas.shape[0], *X0.shape)).copy()
    for i, Xi in enumerate(terms):
        if Xi is not None:
            X += thetas[:, i, None, None] * Xi
    return X


def generalized_modes_batch(K: np.ndarray, M: np.ndarray, n_modes: int) -> BatchModalSolution:
    """Lowest modes of stacked symmetric pencils (B, n, n) via Cholesky of M and numpy's batched eigh.

    Written out because scipy.linalg.eigh does not take stacked matrices; numpy's ``eigh`` and
    ``cholesky`` do, which is what makes thousands of small eigenproblems per second possible.
    """
    L = np.linalg.cholesky(M)
    Linv = np.linalg.inv(L)
    A = Linv @ K @ np.swapaxes(Linv, -1, -2)
    A = 0.5 * (A + np.swapaxes(A, -1, -2))
    w2, y = np.linalg.eigh(A)
    n = min(n_modes, K.shape[-1])
    w2, y = w2[:, :n], y[:, :, :n]
    phi = np.swapaxes(Linv, -1, -2) @ y
    return BatchModalSolution(np.sqrt(np.clip(w2, 0.0, None)) / (2 * np.pi), phi)


def damping_factors_of(params: list[Any]) -> list[list[int]]:
    """Per parameter, the indices of the damping ratios it multiplies (``damping.ratios[i]`` targets)."""
    return [[int(loc[2]) for loc in p.targets if loc[:2] == ("damping", "ratios")] for p in params]


def assemble_model(spec: Any, params: list[Any], K0: np.ndarray, M0: np.ndarray,
                   K_terms: list[np.ndarray], M_terms: list[np.ndarray], dof_labels: list[str],
                   sensor_dofs: dict[str, int], damping_factors: list[list[int]],
                   **fields: Any) -> AffineModel:
    """The :class:`AffineModel` of a structure spec once a builder has its matrices: the parts every
    kind shares (names, all-zero terms dropped, damping, input sensor); ``fields`` adds the rest."""
    fields.setdefault("input_dof", sensor_dofs.get(spec.input_sensor) if spec.input_sensor else None)
    direction = fields.get("direction")
    fields.setdefault("inputs", [i for i in getattr(spec, "inputs", [])
                                 if direction is None or i.direction == direction])
    return AffineModel(
        name=spec.name,
        parameter_names=[p.name for p in params],
        K0=K0,
        M0=M0,
        K_terms=[t if np.any(t) else None for t in K_terms],
        M_terms=[t if np.any(t) else None for t in M_terms],
        dof_labels=dof_labels,
        sensor_dofs=sensor_dofs,
        damping_ratios=tuple(spec.damping.ratios),
        damping_kind=spec.damping.kind,
        input_sensor=spec.input_sensor,
        damping_factors=damping_factors,
        **fields,
    )
