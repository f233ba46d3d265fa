"""Batched modal predictions of an affine model at the measured DOFs.

A predictor maps a batch of parameter vectors ``theta`` (B, d) to model frequencies (B, m) and
model shapes read at the sensors (B, s, m). Two kinds:

* :class:`FullModalPredictor` - the full model's generalised eigenproblem, read at the sensor DOFs.
  When the mass does not depend on theta, ``L^-1 K(theta) L^-T`` is itself affine in theta (L the
  Cholesky factor of M), so a batch costs one stacked ``numpy.linalg.eigh``.
* :class:`ReducedModalPredictor` - IIRS reduction to the measured DOFs first
  (``shm_ros.core.models.reduction``), then the small reduced eigenproblem; the shapes come out at
  the sensors directly and the same transformation expands them to every DOF.
"""

from __future__ import annotations

import weakref
from typing import Protocol

import numpy as np

from shm_ros.core.modal import mac
from shm_ros.core.models.base import AffineModel


class ModalPredictor(Protocol):
    sensor_ids: list[str]
    n_modes: int

    def __call__(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(B, d) -> frequencies (B, m) in Hz, shapes at sensors (B, s, m)."""
        ...


def observation_rows(model: AffineModel, sensor_ids: list[str]) -> np.ndarray:
    """Rows (s, n_dof) reading the data's sensors from the model; clear error for unknown ids."""
    known = set(model.sensor_rows) | set(model.sensor_dofs)
    missing = [s for s in sensor_ids if s not in known]
    if missing:
        raise ValueError(f"sensor id(s) {missing} of the modal data are not sensors of model "
                         f"'{model.name}' (known: {sorted(known)})")
    return model.sensor_matrix(list(sensor_ids)) if sensor_ids else np.zeros((0, model.n_dof))


def _stack_terms(terms: list[np.ndarray | None], n: int) -> tuple[np.ndarray, np.ndarray]:
    """Affine terms as one array (d, n, n) plus a mask of the parameters that act."""
    acts = np.array([t is not None and np.any(t) for t in terms], dtype=bool)
    arr = np.zeros((len(terms), n, n))
    for i, t in enumerate(terms):
        if acts[i]:
            arr[i] = np.asarray(t, dtype=float)
    return arr, acts


def _frequencies(w2: np.ndarray) -> np.ndarray:
    return np.sqrt(np.clip(w2, 0.0, None)) / (2.0 * np.pi)


class FullModalPredictor:
    """Lowest ``n_modes`` of the full model for a batch of theta, shapes read at ``sensor_ids``."""

    def __init__(self, model: AffineModel, sensor_ids: list[str], n_modes: int):
        self.model = model
        self.sensor_ids = list(sensor_ids)
        self.n_modes = int(min(n_modes, model.n_dof))
        self.S = observation_rows(model, self.sensor_ids)
        n = model.n_dof
        self._Kt, _ = _stack_terms(model.K_terms, n)
        self._Mt, m_acts = _stack_terms(model.M_terms, n)
        self.mass_varies = bool(m_acts.any())
        if not self.mass_varies:
            L = np.linalg.cholesky(model.M0)
            Linv = np.linalg.inv(L)
            self._Linv_T = Linv.T
            self._A0 = Linv @ model.K0 @ Linv.T
            self._At = np.einsum("ij,djk,lk->dil", Linv, self._Kt, Linv)

    def __call__(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        m = self.n_modes
        if not self.mass_varies:
            A = self._A0[None] + np.tensordot(theta, self._At, axes=(1, 0))
            w2, v = np.linalg.eigh(A)
            phi = self._Linv_T[None] @ v[:, :, :m]
        else:
            K = self.model.K0[None] + np.tensordot(theta, self._Kt, axes=(1, 0))
            M = self.model.M0[None] + np.tensordot(theta, self._Mt, axes=(1, 0))
            L = np.linalg.cholesky(M)
            Linv = np.linalg.inv(L)
            A = Linv @ K @ np.swapaxes(Linv, 1, 2)
            w2, v = np.linalg.eigh(A)
            phi = np.swapaxes(Linv, 1, 2) @ v[:, :, :m]
        return _frequencies(w2[:, :m]), self.S[None] @ phi

    def full_shapes(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Frequencies (m,) and mass-normalised shapes at every DOF (n, m) for one theta."""
        sol = self.model.modes(np.asarray(theta, dtype=float), n_modes=self.n_modes)
        return sol.frequencies_hz, sol.shapes


class ReducedModalPredictor:
    """IIRS reduction to the sensors' DOFs inside the likelihood, batched over theta.

    The reduced model has one DOF per distinct sensor DOF, hence at most that many modes. The IIRS
    iteration is warm-started from the transformation of the previous batch (theta moves little
    between sampler steps), which saves most iterations; convergence does not depend on the start.
    """

    def __init__(self, model: AffineModel, sensor_ids: list[str], n_modes: int,
                 max_iter: int = 200, tol: float = 1e-8):
        from shm_ros.core.models.reduction import iirs  # noqa: F401 - fail early if missing

        observation_rows(model, sensor_ids)  # clear error for unknown sensors
        self.model = model
        self.sensor_ids = list(sensor_ids)
        dofs = model.master_dofs(self.sensor_ids)
        self.masters = sorted(set(dofs))
        self.sensor_pos = np.array([self.masters.index(dof) for dof in dofs], dtype=int)
        self.n_modes = int(min(n_modes, len(self.masters)))
        self.max_iter, self.tol = max_iter, tol
        self._t0: np.ndarray | None = None
        self.last_converged = True

    def reduce(self, theta: np.ndarray):
        from shm_ros.core.models.reduction import iirs

        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        K = self.model.stiffness_batch(theta)
        M = self.model.mass_batch(theta)
        R = iirs(K, M, self.masters, max_iter=self.max_iter, tol=self.tol, t0=self._t0)
        if not R.converged:  # a poor warm start: redo from the static (Guyan) start
            R = iirs(K, M, self.masters, max_iter=self.max_iter, tol=self.tol)
        self.last_converged = bool(R.converged)
        if R.converged:
            self._t0 = R.t[0].copy()
        return R

    def __call__(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        from shm_ros.core.models.base import generalized_modes_batch

        R = self.reduce(theta)
        sol = generalized_modes_batch(R.K, R.M, self.n_modes)
        return sol.frequencies_hz, sol.shapes[:, self.sensor_pos, :]

    def full_shapes(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Frequencies (m,) and reduced shapes expanded to every DOF with the same T (n, m)."""
        from shm_ros.core.models.base import generalized_modes_batch

        R = self.reduce(np.atleast_2d(theta))
        sol = generalized_modes_batch(R.K, R.M, self.n_modes)
        return sol.frequencies_hz[0], (R.T @ sol.shapes)[0]


def can_reduce(model: AffineModel, sensor_ids: list[str], n_required: int) -> bool:
    try:
        dofs = set(model.master_dofs(list(sensor_ids)))
    except KeyError:
        return False
    return n_required <= len(dofs) < model.n_dof


def build_predictor(model: AffineModel, sensor_ids: list[str], n_modes: int,
                    reduction: str = "auto", n_required: int | None = None) -> ModalPredictor:
    """Full or IIRS-reduced predictor.

    ``iirs`` reduces to the sensors' DOFs (error when a sensor does not sit on a DOF or the sensors
    cannot carry ``n_required`` modes); ``none`` uses the full model. ``auto`` builds both when
    reduction is possible, checks that the reduced model reproduces the full model's frequencies of
    the required modes (relative difference < 1e-6) and keeps the faster one on a trial batch: the
    converged IIRS model has the same lowest modes, so the choice is about cost only (a building
    with a few instrumented floors reduces well; a girder whose rotations are never measured is
    cheaper unreduced).
    """
    import time

    n_required = n_modes if n_required is None else n_required
    if reduction == "none" or not sensor_ids:
        return FullModalPredictor(model, sensor_ids, n_modes)
    ok = can_reduce(model, sensor_ids, n_required)
    if reduction == "iirs":
        if not ok:
            raise ValueError(f"IIRS reduction to sensors {sensor_ids} is not possible for model "
                             f"'{model.name}': every sensor must sit on a DOF and the sensors must "
                             f"cover at least {n_required} and fewer than {model.n_dof} DOFs")
        return ReducedModalPredictor(model, sensor_ids, n_modes)
    full = FullModalPredictor(model, sensor_ids, n_modes)
    key = (id(model), tuple(sensor_ids), int(n_modes), int(n_required))
    if not ok or key in _FULL_CHOSEN:
        return full
    reduced = ReducedModalPredictor(model, sensor_ids, n_modes)
    rng = np.random.default_rng(0)
    trial = model.nominal_theta()[None] * (1.0 + 0.02 * rng.standard_normal((64, model.n_parameters)))
    cost = {}
    out = {}
    for name, p in (("full", full), ("iirs", reduced)):
        p(trial[:2])
        runs = []
        for _ in range(3):  # best of three: the machine may be busy
            t0 = time.perf_counter()
            out[name] = p(trial)
            runs.append(time.perf_counter() - t0)
        cost[name] = min(runs)
    f_full, f_red = out["full"][0][:, :n_required], out["iirs"][0][:, :n_required]
    agree = bool(np.all(np.abs(f_red / f_full - 1.0) < 1e-6)) and reduced.last_converged
    if agree and cost["iirs"] < cost["full"]:
        return reduced
    _FULL_CHOSEN[key] = None
    weakref.finalize(model, _FULL_CHOSEN.pop, key, None)
    return full


# ``auto`` choices of the full model, by (model id, sensors, modes): a model updated again and again
# (a node's runs, a study's seeds) is timed once. Only this choice is kept: the full predictor is
# exact and has no state, so keeping it can cost time but never change a result, whereas a reduced
# one comes out of the trial warm-started on its batch, as each run's must. An entry leaves with its
# model, so a later model at the same address is timed afresh.
_FULL_CHOSEN: dict[tuple[int, tuple[str, ...], int, int], None] = {}


class RitzModalPredictor:
    """Rayleigh-Ritz projection of the full model onto modes sampled around a reference theta.

    The basis holds the lowest modes of the full model at ``theta_ref`` and at ``theta_ref +- step_i``
    along every parameter (so it contains the modes and, to first order, their parameter
    derivatives), made mass-orthonormal. The projected matrices stay affine in theta, so a batch
    costs one stacked eigen-solution of a basis-sized matrix instead of a model-sized one. It is an
    approximation valid near ``theta_ref``: :meth:`max_error` measures it against the full model,
    and :func:`shm_ros.core.bayes.update.update` uses it for sampling only when that error is far
    below the data's resolution (the evidence, which explores the whole prior, never uses it).
    """

    def __init__(self, model: AffineModel, sensor_ids: list[str], n_modes: int,
                 theta_ref: np.ndarray, step: np.ndarray, extra_modes: int = 4):
        self.model = model
        self.sensor_ids = list(sensor_ids)
        self.n_modes = int(min(n_modes, model.n_dof))
        theta_ref = np.asarray(theta_ref, dtype=float)
        pts = [theta_ref]
        for i in range(theta_ref.size):
            for sgn in (1.0, -1.0):
                p = theta_ref.copy()
                p[i] += sgn * step[i]
                pts.append(p)
        k = min(self.n_modes + extra_modes, model.n_dof)
        V = np.hstack([model.modes(p, k).shapes for p in pts])
        M_ref = model.mass(theta_ref)
        G = V.T @ M_ref @ V
        w, U = np.linalg.eigh(0.5 * (G + G.T))
        keep = w > 1e-12 * w.max()
        self.V = V @ (U[:, keep] / np.sqrt(w[keep]))
        Kt, _ = _stack_terms(model.K_terms, model.n_dof)
        Mt, m_acts = _stack_terms(model.M_terms, model.n_dof)
        P = self.V
        self._K0 = P.T @ model.K0 @ P
        self._Kt = np.einsum("ni,dnm,mj->dij", P, Kt, P)
        self._M0 = P.T @ model.M0 @ P
        self._Mt = np.einsum("ni,dnm,mj->dij", P, Mt, P)
        self.mass_varies = bool(m_acts.any())
        self.S = observation_rows(model, self.sensor_ids) @ P
        self.basis_size = int(P.shape[1])
        if not self.mass_varies:
            L = np.linalg.cholesky(0.5 * (self._M0 + self._M0.T))
            Li = np.linalg.inv(L)
            self._Li_T = Li.T
            self._A0 = Li @ self._K0 @ Li.T
            self._At = np.einsum("ij,djk,lk->dil", Li, self._Kt, Li)

    def __call__(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        from shm_ros.core.models.base import generalized_modes_batch

        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        m = self.n_modes
        if not self.mass_varies:
            A = self._A0[None] + np.tensordot(theta, self._At, axes=(1, 0))
            w2, y = np.linalg.eigh(A)
            return _frequencies(w2[:, :m]), self.S[None] @ (self._Li_T[None] @ y[:, :, :m])
        K = self._K0[None] + np.tensordot(theta, self._Kt, axes=(1, 0))
        M = self._M0[None] + np.tensordot(theta, self._Mt, axes=(1, 0))
        sol = generalized_modes_batch(K, M, m)
        return sol.frequencies_hz, self.S[None] @ sol.shapes

    def max_error(self, reference: ModalPredictor, theta: np.ndarray, n_check: int) -> tuple[float, float]:
        """Largest relative frequency error and MAC deficit of the first ``n_check`` modes."""
        f_r, p_r = self(theta)
        f_f, p_f = reference(theta)
        ferr = float(np.max(np.abs(f_r[:, :n_check] / f_f[:, :n_check] - 1.0)))
        if p_r.shape[1] == 0:
            return ferr, 0.0
        macs = mac(np.swapaxes(p_r[:, :, :n_check], 1, 2), np.swapaxes(p_f[:, :, :n_check], 1, 2))
        return ferr, float(np.max(1.0 - macs))
