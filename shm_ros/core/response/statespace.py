"""Continuous state space of a model under its inputs: dz/dt = A z + B u, y = C z + D u.

States, in this order: the dynamic displacements w and velocities w' of the free DOFs (see
:mod:`.supports`), the force of each Maxwell damper, and - only where something needs them - the
velocities and displacements of supports (integrals of their measured accelerations: a damper or
an output that spans supports moving differently sees them).

    M w'' + C w' + K w = -(M T_s + M_fs) a_s - sum_m b_m f_m + E v_s + L F
    f_m' = k_m (b_m x' - f_m / c_m)                    (Maxwell: spring and dashpot in series)

with C the inherent damping plus the Kelvin-Voigt dashpots (non-classical), E the dashpots' share
of support velocities, L the force inputs' load rows. Inputs u are the records times their gains,
in the order of the inputs: accelerations (m/s^2) for base and floor inputs, forces (N) for force
inputs.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from shm_ros.core.models.base import AffineModel
from shm_ros.core.structure import InputSpec

from .outputs import Output, Quantity
from .supports import Supports, clean_rows, influence, partition


@dataclass
class StateSpace:
    """Continuous-time (A, B, C, D) with names: ``outputs`` rows of C, ``state_names`` rows of A."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    outputs: list[str]
    state_names: list[str]
    supports: Supports


def build_state_space(model: AffineModel, theta: np.ndarray | None, outputs: Sequence[Output],
                      inputs: Sequence[InputSpec] | None = None) -> StateSpace:
    """The state space of ``model`` at ``theta`` driven by ``inputs`` (default: the model's)."""
    th = model.nominal_theta() if theta is None else np.asarray(theta, dtype=float)
    return build_state_spaces(model, th[None], outputs, inputs)[0]


def build_state_spaces(model: AffineModel, thetas: np.ndarray, outputs: Sequence[Output],
                       inputs: Sequence[InputSpec] | None = None) -> list[StateSpace]:
    """:func:`build_state_space` at every row of ``thetas`` (B, d), assembled as stacked arrays.

    A batch of draws shares its layout (free DOFs, which support motions are states), so the matrices
    are built with batched products; this is what keeps the time-domain likelihood's thousands of
    draws from being bound by Python. Rows whose layout differs (a support motion that becomes a state
    at some theta, or the DOFs the measured floors support) are built apart."""
    ths = np.atleast_2d(np.asarray(thetas, dtype=float))
    inputs = list(model.inputs if inputs is None else inputs)
    sup = partition(model, ths[0], inputs)
    if ths.shape[0] > 1 and not sup.known[-1]:  # the free set follows K's pattern: one partition per row
        return [build_state_spaces(model, th[None], outputs, inputs)[0] for th in ths]
    n, f = model.n_dof, sup.free
    nf, ns, ni, nb = f.size, sup.n_supports, len(inputs), ths.shape[0]
    M, K = model.mass_batch(ths), model.stiffness_batch(ths)
    T = influence(model, K, f, sup.support_dofs)  # from the same K as the rest (not partition's), bit for bit
    ix = np.ix_(np.arange(nb), f, f)
    Cff = (model.inherent_damping_batch(ths) + model.damper_damping()[None])[ix]
    Mff, Kff = M[ix], K[ix]
    Mi = np.linalg.inv(Mff) if nf else np.zeros((nb, 0, 0))
    gains = np.array([i.gain for i in inputs], dtype=float)

    # support accelerations a_s = Sa u, forces on the free DOFs = L u
    Sa = np.zeros((ns, ni))
    L = np.zeros((nf, ni))
    for k in range(ni):
        s = sup.input_support[k]
        if s is not None:
            Sa[s, k] = gains[k]
        else:
            load = sup.loads[k]
            assert load is not None  # a force input has a load row
            L[:, k] = gains[k] * load[f]
    Mfs = np.zeros((nb, nf, ns))
    for s, dof in enumerate(sup.support_dofs):
        if dof is not None:
            Mfs[:, :, s] = M[:, f, dof]
    G = -(Mff @ T[:, f] + Mfs)  # force on w per unit support acceleration

    # dampers: their free part bw (nf,) and support part bs (B, ns) of the extension
    E = np.zeros((nb, nf, ns))
    maxwell: list[tuple[np.ndarray, np.ndarray, float, float]] = []
    for d in model.dampers:
        b = np.zeros(n + 1)
        i, j = d.nodes
        b[n if i is None else i] += 1.0
        b[n if j is None else j] -= 1.0
        bw = b[f]
        if not np.any(bw):
            continue  # both ends driven: the damper only loads the supports
        bs = clean_rows(b @ T)
        if d.k_maxwell is None:
            E -= d.c * bw[None, :, None] * bs[:, None, :]
        else:
            maxwell.append((bw, bs, float(d.k_maxwell), float(d.c)))

    need_d = np.zeros((nb, ns), dtype=bool)
    need_v = np.any(E != 0, axis=1)
    for _, bs, _, _ in maxwell:
        need_v |= bs != 0
    out_rows = []
    for o in outputs:
        row = np.asarray(o.row, dtype=float)
        if np.any(np.abs(row[~sup.known]) > 0):
            raise ValueError(f"output {o.name!r}: its motion depends on the ground, which no input measures "
                             "(with floor inputs only, the system is what the measured floors support)")
        rs = clean_rows(row @ T)
        if o.quantity == Quantity.VELOCITY:
            need_v |= rs != 0
        if o.quantity == Quantity.DISPLACEMENT:
            need_d |= rs != 0
        out_rows.append((o, row[f], rs))
    need_v |= need_d
    key = np.hstack([need_v, need_d])
    if nb == 1 or not np.any(key != key[0]):  # one layout (the usual case): no sort of the rows
        layouts, which = key[:1], np.zeros(nb, int)
    else:
        layouts, which = np.unique(key, axis=0, return_inverse=True)
    out: list[StateSpace | None] = [None] * nb
    parts = _Parts(Mi, Kff, Cff, G, E, Sa, L, maxwell, out_rows)
    for g, lay in enumerate(layouts):
        rows = np.flatnonzero(which.ravel() == g)
        vsel, dsel = np.flatnonzero(lay[:ns]), np.flatnonzero(lay[ns:])
        A, Bm, C, D = _assemble(parts, rows, vsel, dsel)
        names = ([f"w[{model.dof_labels[i]}]" for i in f] + [f"v[{model.dof_labels[i]}]" for i in f]
                 + [f"maxwell{m}" for m in range(len(maxwell))] + [f"support_v{s}" for s in vsel]
                 + [f"support_d{s}" for s in dsel])
        for k, r in enumerate(rows):
            out[r] = StateSpace(A[k], Bm[k], C[k], D[k], [o.name for o in outputs], names,
                                dataclasses.replace(sup, T=T[r]))
    return [s for s in out if s is not None]


@dataclass
class _Parts:
    """The theta-dependent blocks of a batch (leading axis B) and the layout-independent constants."""

    Mi: np.ndarray
    Kff: np.ndarray
    Cff: np.ndarray
    G: np.ndarray
    E: np.ndarray
    Sa: np.ndarray
    L: np.ndarray
    maxwell: list[tuple[np.ndarray, np.ndarray, float, float]]
    out_rows: list[tuple[Output, np.ndarray, np.ndarray]]


def _assemble(p: _Parts, rows: np.ndarray, vsel: np.ndarray, dsel: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(A, B, C, D) stacked for the batch ``rows`` sharing the support states ``vsel``, ``dsel``."""
    nb, nf, ni = rows.size, p.Kff.shape[1], p.Sa.shape[1]
    nm, nv, nd = len(p.maxwell), vsel.size, dsel.size
    Mi = p.Mi[rows]
    nz = 2 * nf + nm + nv + nd
    iw, iv_, im, isv, isd = 0, nf, 2 * nf, 2 * nf + nm, 2 * nf + nm + nv
    A = np.zeros((nb, nz, nz))
    B = np.zeros((nb, nz, ni))
    A[:, iw:iw + nf, iv_:iv_ + nf] = np.eye(nf)
    # accelerations of w: the rows every acceleration output reuses
    Aacc = np.zeros((nb, nf, nz))
    Aacc[:, :, iw:iw + nf] = -Mi @ p.Kff[rows]
    Aacc[:, :, iv_:iv_ + nf] = -Mi @ p.Cff[rows]
    for m, (bw, bs, km, c) in enumerate(p.maxwell):
        Aacc[:, :, im + m] = -Mi @ bw
        A[:, im + m, iv_:iv_ + nf] = km * bw
        A[:, im + m, im + m] = -km / c
        A[:, im + m, isv:isv + nv] = km * bs[rows][:, vsel]
    Aacc[:, :, isv:isv + nv] = Mi @ p.E[rows][:, :, vsel]
    Bacc = Mi @ (p.G[rows] @ p.Sa + p.L)
    A[:, iv_:iv_ + nf] = Aacc
    B[:, iv_:iv_ + nf] = Bacc
    B[:, isv:isv + nv] = p.Sa[vsel]
    pos_v = {int(v): k for k, v in enumerate(vsel)}
    for k, v in enumerate(dsel):
        A[:, isd + k, isv + pos_v[int(v)]] = 1.0

    C = np.zeros((nb, len(p.out_rows), nz))
    D = np.zeros((nb, len(p.out_rows), ni))
    for r, (o, rw, rs) in enumerate(p.out_rows):
        if o.quantity == Quantity.ACCELERATION:
            C[:, r] = rw @ Aacc
            D[:, r] = rw @ Bacc + rs[rows] @ p.Sa
        elif o.quantity == Quantity.VELOCITY:
            C[:, r, iv_:iv_ + nf] = rw
            C[:, r, isv:isv + nv] = rs[rows][:, vsel]
        else:
            C[:, r, iw:iw + nf] = rw
            C[:, r, isd:isd + nd] = rs[rows][:, dsel]
    return A, B, C, D
