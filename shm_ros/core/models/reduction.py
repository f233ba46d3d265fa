"""Reduction to the measured DOFs (IIRS) and expansion of mode shapes back to all DOFs.

Partition the DOFs into masters ``m`` (measured) and slaves ``s``. A transformation
``T = [I; t]`` (masters first) maps master motion to all DOFs, and the reduced matrices are
``K_R = T' K T``, ``M_R = T' M T``. Guyan (static) reduction takes ``t = -Kss^-1 Ksm``; the improved
reduced system adds the slaves' inertia, and iterating it (IIRS) gives

    t_{k+1} = -Kss^-1 Ksm + Kss^-1 (Msm + Mss t_k) M_R(t_k)^-1 K_R(t_k)

which converges to the transformation whose reduced model reproduces the full model's lowest
``len(masters)`` modes exactly (a subspace iteration on the slave DOFs). Mode-shape expansion uses
the same ``T``: ``phi_full = T phi_m``.

Everything accepts single matrices (n, n) or stacks (B, n, n) and works on the stack with numpy's
batched linear algebra, which is what makes tens of thousands of reduced modal solutions per second
possible inside a likelihood. Written here because scipy has no IIRS; the algebra is a few lines.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from shm_ros.core.models.base import AffineModel, BatchModalSolution, ModalSolution, generalized_modes_batch

_CONTROLLER = None
R_MAX = 0.9  # largest convergence ratio the extrapolation trusts (jump factor <= 10)


def _as_stack(K: np.ndarray, M: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """One (n, n) pencil or a (B, n, n) stack -> float stacks, and whether it was a single one."""
    K = np.asarray(K, dtype=float)
    M = np.asarray(M, dtype=float)
    if K.ndim == 2:
        return K[None], M[None], True
    return K, M, False


@contextlib.contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Run the block with one BLAS thread (via threadpoolctl when installed).

    Stacks of tiny matrices are slower, not faster, when OpenBLAS splits each product over threads;
    batched reductions run inside this, and callers may parallelise over processes instead.
    """
    global _CONTROLLER
    try:
        if _CONTROLLER is None:
            from threadpoolctl import ThreadpoolController

            _CONTROLLER = ThreadpoolController()
        ctx = _CONTROLLER.limit(limits=1, user_api="blas")
    except ImportError:  # pragma: no cover - threadpoolctl is a runtime dependency
        ctx = contextlib.nullcontext()
    with ctx:
        yield


@dataclass
class Reduction:
    """Result of a reduction; arrays carry a leading batch axis when the input was stacked.

    ``T`` (n, m) maps master DOFs (in ``masters`` order) to all DOFs (model order); ``K``/``M`` are
    the reduced (m, m) matrices. ``iterations`` run and ``converged`` (relative change of the reduced
    eigenvalue invariants trace(M_R^-1 K_R) and trace(K_R^-1 M_R) below the tolerance for every
    batch member).
    """

    T: np.ndarray
    K: np.ndarray
    M: np.ndarray
    masters: list[int]
    iterations: int
    converged: bool
    change: float = 0.0  # final max relative change of the reduced-eigenvalue invariants
    not_converged: np.ndarray | None = None  # batch positions that hit max_iter (None: all converged)

    @property
    def t(self) -> np.ndarray:
        """Slave block of ``T`` ((s, m) or (B, s, m)), usable as ``t0`` to warm-start ``iirs``."""
        return self.T[..., _others(self.T.shape[-2], self.masters), :]

    @property
    def batched(self) -> bool:
        return self.T.ndim == 3

    def modes(self, n_modes: int | None = None) -> ModalSolution | BatchModalSolution:
        """Modes of the reduced model; shapes are at the masters (m, n_modes), M_R-normalised."""
        n = len(self.masters) if n_modes is None else min(n_modes, len(self.masters))
        if self.batched:
            return generalized_modes_batch(self.K, self.M, n)
        sol = generalized_modes_batch(self.K[None], self.M[None], n)
        return ModalSolution(sol.frequencies_hz[0], sol.shapes[0])

    def expand(self, shapes_m: np.ndarray) -> np.ndarray:
        """Expand master-DOF shapes (m, k) - or (B, m, k) for a batch - to all DOFs with ``T``."""
        return expand_mode_shapes(self.T, shapes_m)


def _split(n: int, masters: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    m = np.asarray(list(masters), dtype=int)
    if m.size == 0:
        raise ValueError("need at least one master DOF")
    if len(set(m.tolist())) != m.size or m.min() < 0 or m.max() >= n:
        raise ValueError(f"masters must be distinct DOF indices in [0, {n}), got {list(masters)}")
    return m, _others(n, m)


def _others(n: int, masters: Sequence[int] | np.ndarray) -> np.ndarray:
    """The DOFs of ``range(n)`` that are not masters, ascending (``np.setdiff1d`` without its
    sort: a likelihood reduces thousands of times)."""
    keep = np.ones(n, dtype=bool)
    keep[np.asarray(masters, dtype=int)] = False
    return np.flatnonzero(keep)


def _assemble_T(t: np.ndarray, m: np.ndarray, s: np.ndarray, n: int) -> np.ndarray:
    B = t.shape[0]
    T = np.zeros((B, n, m.size))
    T[:, m, np.arange(m.size)] = 1.0
    T[:, s, :] = t
    return T


def _reduced(Kmm, Kms, Kss, t):
    """T' K T for T = [I; t] from the blocks (batched)."""
    tT = np.swapaxes(t, -1, -2)
    Kmst = Kms @ t
    R = Kmm + Kmst + np.swapaxes(Kmst, -1, -2) + tT @ Kss @ t
    return 0.5 * (R + np.swapaxes(R, -1, -2))


def iirs(
    K: np.ndarray,
    M: np.ndarray,
    masters: Sequence[int],
    max_iter: int = 500,
    tol: float = 1e-9,
    improved: bool = True,
    t0: np.ndarray | None = None,
    accelerate: bool = True,
) -> Reduction:
    """IIRS reduction of (K, M) - single (n, n) or stacked (B, n, n) - to ``masters``.

    ``improved=False`` gives Guyan reduction (no iteration). Iteration stops when, for every batch
    member, the reduced eigenvalue invariants change by less than ``tol`` (relative) between two
    iterations, or after ``max_iter`` iterations. The reduced eigenvalues' own error is then of the
    order of ``tol`` (frequencies half of that). ``t0`` (s, m) or (B, s, m) warm-starts the
    iteration (e.g. the slave block ``Reduction.t`` of a nearby theta) instead of Guyan.
    ``accelerate`` extrapolates the geometric convergence every third step (same fixed point,
    fewer iterations); ``accelerate=False`` is the plain iteration.
    """
    K, M, single = _as_stack(K, M)
    n = K.shape[-1]
    m, s = _split(n, masters)
    if s.size == 0:
        T = _assemble_T(np.zeros((K.shape[0], 0, m.size)), m, s, n)
        R = Reduction(T, K[:, m][:, :, m], M[:, m][:, :, m], list(m), 0, True)
        return _unbatch(R) if single else R

    Kmm, Kms, Kss = K[:, m][:, :, m], K[:, m][:, :, s], K[:, s][:, :, s]
    Mmm, Mms, Mss = M[:, m][:, :, m], M[:, m][:, :, s], M[:, s][:, :, s]
    Ksm = np.swapaxes(Kms, -1, -2)
    Kss_inv = np.linalg.inv(Kss)
    tG = -Kss_inv @ Ksm
    if t0 is not None:
        t = np.broadcast_to(np.asarray(t0, dtype=float), tG.shape).copy()
    else:
        t = tG
    it = 0
    change = 0.0
    converged = not improved
    if improved:
        with single_threaded_blas():
            t, it, change, converged, stragglers = _iterate(
                Kmm, Kms, Kss, Mmm, Mms, Mss, tG, Kss_inv, t, m.size, max_iter, tol, accelerate
            )
    KR = _reduced(Kmm, Kms, Kss, t)
    MR = _reduced(Mmm, Mms, Mss, t)
    R = Reduction(_assemble_T(t, m, s, n), KR, MR, list(m), it, converged, change)
    if improved and not converged:
        R.not_converged = stragglers
    return _unbatch(R) if single else R


def _iterate(Kmm, Kms, Kss, Mmm, Mms, Mss, tG, Kss_inv, t, n_masters, max_iter, tol, accelerate=True):
    """The IIRS fixed-point iteration on a batch, each member stopping when it has converged.

    With ``t = tG + d`` the reduced stiffness is ``K_G + d' Kss d`` (the Guyan cross terms vanish),
    and ``Kss d`` is a by-product of the update, so one iteration costs six small matrix products
    and one solve:  P = Msm + Mss t;  M_R = Mmm + Mms t + t' P;  D = M_R^-1 K_R;  Y = P D;
    d = Kss^-1 Y;  K_R = K_G + d' Y;  t = tG + d.

    Convergence is judged on the reduced eigenvalues through trace(M_R^-1 K_R), which is dominated
    by the highest reduced mode; that mode converges slowest (rate lambda_m / lambda_{m+1} per
    iteration, lower modes faster). ``t`` itself converges more slowly than the modes, so it is not
    the criterion. The trace tolerance is tol / m so that each eigenvalue's change is below tol.
    Converged members leave the working set, so a few slow members do not cost the whole batch.

    The error decays geometrically (ratio r ~ lambda_m / lambda_{m+1}). With ``accelerate`` the
    ratio of successive step sizes estimates r; every third step, where two successive estimates
    agree (a clean geometric regime), members jump to the limit of the series, t + step / (1 - r),
    and a change measured across a jump does not count. The fixed point is unchanged; only the
    iterations to reach it drop.

    The loop runs compiled (:func:`shm_ros.core.models.iirs_kernel.iterate`): at the sizes of a
    likelihood (a dozen members, a few DOFs) numpy's per-call overhead costs many times the
    arithmetic. Returns (t, iterations, last change, converged, members that did not converge).
    """
    from shm_ros.core.models.iirs_kernel import SINGULAR, iterate

    if min(t.shape[-2:]) == 1:
        return _iterate_numpy(Kmm, Kms, Kss, Mmm, Mms, Mss, tG, Kss_inv, t, n_masters, max_iter, tol, accelerate)
    t = np.array(t, dtype=float, order="C")
    KG = Kmm + Kms @ tG
    d = t - tG
    KR = np.ascontiguousarray(KG + np.swapaxes(d, -1, -2) @ Kss @ d)
    active = np.ones(t.shape[0], dtype=bool)
    Mmm, Mms, Mss, tG, Kss_inv, KG, Kss = (np.ascontiguousarray(a, dtype=float)
                                           for a in (Mmm, Mms, Mss, tG, Kss_inv, KG, Kss))
    status, it, change = iterate(Mmm, Mms, Mss, tG, Kss_inv, KG, Kss, t, KR, tol / n_masters,
                                 int(max_iter), bool(accelerate), R_MAX, active)
    if status == SINGULAR:  # as np.linalg.solve raises
        raise np.linalg.LinAlgError("Singular matrix")
    converged = status == 1
    return t, it, float(change), converged, None if converged else np.flatnonzero(active)


def _iterate_numpy(Kmm, Kms, Kss, Mmm, Mms, Mss, tG, Kss_inv, t, n_masters, max_iter, tol, accelerate=True):
    """:func:`_iterate` in numpy, batched over the members (the reference of the compiled loop, and
    used where numpy's products of a one-column or one-row matrix are not BLAS's matrix product)."""
    t = t.copy()
    tol_trace = tol / n_masters
    KG = Kmm + Kms @ tG
    Msm = np.swapaxes(Mms, -1, -2)
    d = t - tG
    KR = KG + np.swapaxes(d, -1, -2) @ Kss @ d
    active = np.arange(t.shape[0])
    work = [Mmm, Mms, Msm, Mss, tG, Kss_inv, KG, Kss]
    tw = t
    prev = None
    step_prev = None
    r_prev = None
    jumped_mask = None
    change_max = 0.0
    it = 0
    for it in range(1, max_iter + 1):
        mmm, mms, msm, mss, tg, kinv, kg, kss = work
        P = msm + mss @ tw
        MR = mmm + mms @ tw + np.swapaxes(tw, -1, -2) @ P
        D = np.linalg.solve(MR, KR)  # M_R^-1 K_R
        tr = np.trace(D, axis1=-2, axis2=-1)
        if prev is not None:
            rel = np.abs(tr - prev) / np.abs(tr)
            done = rel < tol_trace
            if jumped_mask is not None:  # a change measured across a jump does not count
                done &= ~jumped_mask
            if done.all():
                t[active] = tw
                return t, it, float(rel.max()), True, None
            change_max = float(rel.max())
            if done.any():
                t[active[done]] = tw[done]
                keep = ~done
                active = active[keep]
                work = [w[keep] for w in work]
                mmm, mms, msm, mss, tg, kinv, kg, kss = work
                tw, D, tr, P = tw[keep], D[keep], tr[keep], P[keep]
                if step_prev is not None:
                    step_prev = step_prev[keep]
                if r_prev is not None:
                    r_prev = r_prev[keep]
                if jumped_mask is not None:
                    jumped_mask = jumped_mask[keep]
        prev = tr
        Y = P @ D
        d = kinv @ Y
        t_new = tg + d
        step = t_new - tw
        jumped = False
        jumped_mask = None
        if accelerate and step_prev is not None:
            # The error decays geometrically (ratio r ~ lambda_m / lambda_{m+1}). The ratio of
            # successive step sizes estimates r; every third step, where two successive estimates
            # agree (a clean geometric regime), jump to the limit of the series, t + step / (1 - r).
            # The fixed point is unchanged; only the iterations to reach it drop.
            num = np.sum(step * step, axis=(-2, -1))
            den = np.sum(step_prev * step_prev, axis=(-2, -1))
            with np.errstate(divide="ignore", invalid="ignore"):
                r = np.sqrt(num / den)
            if it % 3 == 0 and r_prev is not None:
                ok = np.isfinite(r) & (r < R_MAX) & (np.abs(r - r_prev) < 0.02 * r + 1e-3)
                if ok.any():
                    t_new = tw + step / (1.0 - np.where(ok, r, 0.0))[:, None, None]
                    d = t_new - tg
                    jumped, jumped_mask = True, ok
            r_prev = r
        KR = kg + np.swapaxes(d, -1, -2) @ ((kss @ d) if jumped else Y)
        step_prev = step
        tw = t_new
    t[active] = tw
    return t, it, change_max, False, active


def guyan(K: np.ndarray, M: np.ndarray, masters: Sequence[int]) -> Reduction:
    """Guyan (static) reduction: the first step of IIRS."""
    return iirs(K, M, masters, improved=False)


def _unbatch(R: Reduction) -> Reduction:
    return Reduction(R.T[0], R.K[0], R.M[0], R.masters, R.iterations, R.converged, R.change, R.not_converged)


def expand_mode_shapes(T: np.ndarray, shapes_m: np.ndarray) -> np.ndarray:
    """``T @ shapes_m``: shapes at the masters (m,) / (m, k) / (B, m, k) to all DOFs."""
    return np.matmul(T, shapes_m)


def iirs_limit(K: np.ndarray, M: np.ndarray, masters: Sequence[int]) -> Reduction:
    """The converged IIRS reduction computed directly from the full model's lowest m eigenvectors.

    The fixed point of the IIRS iteration is ``T = Phi_L Phi_mL^-1`` (``Phi_L``: the lowest m mass-
    normalised modes, ``Phi_mL`` their master rows), i.e. the SEREP transformation; with it the
    reduced model reproduces those modes exactly. For small models (a shear building) one batched
    eigen-solution is several times cheaper than the iteration; for large models use :func:`iirs`.
    Ill-conditioned when a low mode has (nearly) no motion at all masters - then the sensors cannot
    see it either.
    """
    K, M, single = _as_stack(K, M)
    n = K.shape[-1]
    m, _ = _split(n, masters)
    with single_threaded_blas():
        phi = generalized_modes_batch(K, M, m.size).shapes  # (B, n, m)
        phi_m = phi[:, m, :]
        # T = phi phi_m^-1, solved as phi_m^T T^T = phi^T
        T = np.swapaxes(np.linalg.solve(np.swapaxes(phi_m, -1, -2), np.swapaxes(phi, -1, -2)), -1, -2)
        T[:, m, :] = np.eye(m.size)
        Tt = np.swapaxes(T, -1, -2)
        KR, MR = Tt @ K @ T, Tt @ M @ T
    KR = 0.5 * (KR + np.swapaxes(KR, -1, -2))
    MR = 0.5 * (MR + np.swapaxes(MR, -1, -2))
    R = Reduction(T, KR, MR, list(m), 0, True, 0.0)
    return _unbatch(R) if single else R


def reduce_model(
    model: AffineModel,
    thetas: np.ndarray | None = None,
    sensor_ids: Sequence[str] | None = None,
    masters: Sequence[int] | None = None,
    max_iter: int = 500,
    tol: float = 1e-9,
    method: str = "iterate",
    t0: np.ndarray | None = None,
    accelerate: bool = True,
) -> Reduction:
    """IIRS reduction of ``model`` at ``thetas`` ((p,) -> single, (B, p) -> batch) to the DOFs of
    ``sensor_ids`` (default: every sensor on a DOF), or to explicit ``masters`` DOF indices.

    ``method``: ``"iterate"`` (the IIRS iteration, :func:`iirs`, warm-started from ``t0`` if given)
    or ``"limit"`` (its converged result from the lowest eigenvectors, :func:`iirs_limit`).
    """
    if masters is None:
        masters = model.master_dofs(list(sensor_ids) if sensor_ids is not None else None)
    theta = model.nominal_theta() if thetas is None else np.asarray(thetas, dtype=float)
    if theta.ndim == 1:
        K, M = model.stiffness(theta), model.mass(theta)
    else:
        K, M = model.stiffness_batch(theta), model.mass_batch(theta)
    if method == "limit":
        return iirs_limit(K, M, masters)
    if method != "iterate":
        raise ValueError(f"method must be 'iterate' or 'limit', got {method!r}")
    return iirs(K, M, masters, max_iter=max_iter, tol=tol, t0=t0, accelerate=accelerate)


def reduced_modes_batch(
    model: AffineModel,
    thetas: np.ndarray,
    sensor_ids: Sequence[str] | None = None,
    n_modes: int | None = None,
    max_iter: int = 500,
    tol: float = 1e-9,
    expand: bool = False,
    method: str = "iterate",
) -> BatchModalSolution:
    """Reduced-model modes for every row of ``thetas`` (B, p): frequencies (B, k) and shapes at the
    sensors (B, n_sensors, k) in ``sensor_ids`` order, or expanded to all DOFs when ``expand``.
    Shapes are normalised to the reduced mass matrix."""
    R = reduce_model(model, np.atleast_2d(thetas), sensor_ids, max_iter=max_iter, tol=tol, method=method)
    with single_threaded_blas():
        sol = R.modes(n_modes)
    assert isinstance(sol, BatchModalSolution)  # a reduction of a batch of thetas
    if expand:
        return BatchModalSolution(sol.frequencies_hz, R.expand(sol.shapes))
    return sol


def expand_sensor_shapes(
    model: AffineModel,
    sensor_ids: Sequence[str],
    shapes: np.ndarray,
    theta: np.ndarray | None = None,
    method: str = "iterate",
) -> np.ndarray:
    """Expand mode shapes measured at ``sensor_ids`` ((n_sensors,) or (n_sensors, k)) to every DOF
    of ``model`` at ``theta``, with the IIRS transformation to those sensors' DOFs.

    Sensors that share a DOF are averaged; sensors not on a DOF (girder sensors read by shape
    functions, a building's ground sensor) raise KeyError - place girder sensors on nodes
    (``build_model(spec, sensor_nodes=True)``, the default) to expand girder shapes.
    """
    shapes = np.asarray(shapes, dtype=float)
    vector = shapes.ndim == 1
    if vector:
        shapes = shapes[:, None]
    if shapes.shape[0] != len(sensor_ids):
        raise ValueError(f"shapes have {shapes.shape[0]} rows but {len(sensor_ids)} sensors were given")
    dofs = model.master_dofs(list(sensor_ids))
    masters = sorted(set(dofs))
    at_masters = np.zeros((len(masters), shapes.shape[1]))
    counts = np.zeros(len(masters))
    for row, dof in enumerate(dofs):
        at_masters[masters.index(dof)] += shapes[row]
        counts[masters.index(dof)] += 1
    at_masters /= counts[:, None]
    red = reduce_model(model, theta, masters=masters, method=method)
    full = red.expand(at_masters)
    return full[:, 0] if vector else full
