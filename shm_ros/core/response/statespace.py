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

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from shm_ros.core.models.base import AffineModel
from shm_ros.core.structure import InputSpec

from .outputs import Output, Quantity
from .supports import _TOL, Supports, partition


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
    inputs = list(model.inputs if inputs is None else inputs)
    sup = partition(model, th, inputs)
    n, f = model.n_dof, sup.free
    nf, ns, ni = f.size, sup.n_supports, len(inputs)
    M, K = model.mass(th), model.stiffness(th)
    Cff = model.inherent_damping(th)[np.ix_(f, f)] + model.damper_damping()[np.ix_(f, f)]
    Mff, Kff = M[np.ix_(f, f)], K[np.ix_(f, f)]
    Mi = np.linalg.inv(Mff) if nf else np.zeros((0, 0))
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
    Ts = sup.T[f]  # (nf, ns)
    Mfs = np.zeros((nf, ns))
    for s, dof in enumerate(sup.support_dofs):
        if dof is not None:
            Mfs[:, s] = M[f, dof]
    G = -(Mff @ Ts + Mfs)  # force on w per unit support acceleration

    # dampers: their free part bw (nf,) and support part bs (ns,) of the extension
    E = np.zeros((nf, ns))
    maxwell: list[tuple[np.ndarray, np.ndarray, float, float]] = []
    for d in model.dampers:
        b = np.zeros(n + 1)
        i, j = d.nodes
        b[n if i is None else i] += 1.0
        b[n if j is None else j] -= 1.0
        bw = b[f]
        if not np.any(bw):
            continue  # both ends driven: the damper only loads the supports
        bs = _clean(b @ sup.T)
        if d.k_maxwell is None:
            E -= d.c * np.outer(bw, bs)
        else:
            maxwell.append((bw, bs, float(d.k_maxwell), float(d.c)))
    nm = len(maxwell)

    need_d = np.zeros(ns, dtype=bool)
    need_v = np.any(E != 0, axis=0)
    for _, bs, _, _ in maxwell:
        need_v |= bs != 0
    out_rows = []
    for o in outputs:
        row = np.asarray(o.row, dtype=float)
        if np.any(np.abs(row[~sup.known]) > 0):
            raise ValueError(f"output {o.name!r}: its motion depends on the ground, which no input measures "
                             "(with floor inputs only, the system is what the measured floors support)")
        rw, rs = row[f], _clean(row @ sup.T)
        if o.quantity == Quantity.VELOCITY:
            need_v |= rs != 0
        if o.quantity == Quantity.DISPLACEMENT:
            need_d |= rs != 0
        out_rows.append((o, rw, rs))
    need_v |= need_d
    vsel, dsel = np.flatnonzero(need_v), np.flatnonzero(need_d)
    nv, nd = vsel.size, dsel.size

    nz = 2 * nf + nm + nv + nd
    iw, iv_, im, isv, isd = 0, nf, 2 * nf, 2 * nf + nm, 2 * nf + nm + nv
    A = np.zeros((nz, nz))
    B = np.zeros((nz, ni))
    A[iw:iw + nf, iv_:iv_ + nf] = np.eye(nf)
    # accelerations of w: the rows every acceleration output reuses
    Aacc = np.zeros((nf, nz))
    Aacc[:, iw:iw + nf] = -Mi @ Kff
    Aacc[:, iv_:iv_ + nf] = -Mi @ Cff
    for m, (bw, bs, km, c) in enumerate(maxwell):
        Aacc[:, im + m] = -Mi @ bw
        A[im + m, iv_:iv_ + nf] = km * bw
        A[im + m, im + m] = -km / c
        A[im + m, isv:isv + nv] = km * bs[vsel]
    Aacc[:, isv:isv + nv] = Mi @ E[:, vsel]
    Bacc = Mi @ (G @ Sa + L)
    A[iv_:iv_ + nf] = Aacc
    B[iv_:iv_ + nf] = Bacc
    B[isv:isv + nv] = Sa[vsel]
    pos_v = {int(v): k for k, v in enumerate(vsel)}
    for k, v in enumerate(dsel):
        A[isd + k, isv + pos_v[int(v)]] = 1.0

    C = np.zeros((len(out_rows), nz))
    D = np.zeros((len(out_rows), ni))
    pos_d = {int(v): k for k, v in enumerate(dsel)}
    for r, (o, rw, rs) in enumerate(out_rows):
        if o.quantity == Quantity.ACCELERATION:
            C[r] = rw @ Aacc
            D[r] = rw @ Bacc + rs @ Sa
        elif o.quantity == Quantity.VELOCITY:
            C[r, iv_:iv_ + nf] = rw
            for v in np.flatnonzero(rs):
                C[r, isv + pos_v[int(v)]] = rs[v]
        else:
            C[r, iw:iw + nf] = rw
            for v in np.flatnonzero(rs):
                C[r, isd + pos_d[int(v)]] = rs[v]
    names = ([f"w[{model.dof_labels[i]}]" for i in f] + [f"v[{model.dof_labels[i]}]" for i in f]
             + [f"maxwell{m}" for m in range(nm)] + [f"support_v{s}" for s in vsel] + [f"support_d{s}" for s in dsel])
    return StateSpace(A, B, C, D, [o.name for o in outputs], names, sup)


def _clean(v: np.ndarray) -> np.ndarray:
    """Zero the round-off of exact zeros (a rigid motion's extension computed through K^-1)."""
    v = np.array(v, dtype=float)
    v[np.abs(v) < _TOL * max(1.0, float(np.max(np.abs(v), initial=0.0)))] = 0.0
    return v
