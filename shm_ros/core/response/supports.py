"""Which DOFs move freely and which are driven, for a model under a list of inputs.

Every ``base`` or ``floor`` input is a *support* whose acceleration is measured: ``base`` is the
ground (it moves the DOFs through the model's base influence vector), ``floor`` prescribes the
motion of one DOF. The other DOFs are *free*. Their absolute displacement is split into the
quasi-static motion that the supports impose and a dynamic part w,

    x_f = T_s s + w,    T_s = K_ff^-1 (K r)_f  (ground)   and   -K_ff^-1 K_fp  (prescribed DOFs),

with which the elastic forces involve w alone. The inherent damping of the model (Rayleigh or
modal, restricted to the free DOFs) acts on w; discrete dampers act on the true relative motion of
their ends.

The ground is at rest when no base input is given, unless a floor input is: then the ground's
motion is unknown, and the free DOFs that are coupled to the ground without passing through a
prescribed DOF (a building's floors below the lowest measured floor) are left out: the system is
what the measured floors support. A model without a base influence vector (girder, matrices)
stands on ground at rest.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.sparse.csgraph import connected_components

from shm_ros.core.models.base import AffineModel
from shm_ros.core.structure import InputKind, InputSpec

_TOL = 1e-9  # coefficients below this (relative to 1) are round-off of exact zeros


@dataclass
class Supports:
    """The partition of a model's DOFs under its inputs.

    ``free``: DOF indices of the system; ``support_dofs``: per support, its DOF (None: the ground);
    ``input_support[i]``: the support input i drives (None: a force input); ``loads[i]``: the load
    row (n_dof,) of force input i (None otherwise); ``T``: (n_dof + 1, n_supports) absolute
    displacement of every node (DOFs, then the ground) per unit support displacement, quasi-static;
    ``known``: (n_dof + 1,) nodes whose motion the inputs determine (False: left out).
    """

    free: np.ndarray
    support_dofs: list[int | None]
    input_support: list[int | None]
    loads: list[np.ndarray | None]
    T: np.ndarray
    known: np.ndarray
    ground_moves: bool

    @property
    def n_supports(self) -> int:
        return len(self.support_dofs)


def _dof_of(model: AffineModel, inp: InputSpec) -> int:
    row = model.location_row(inp.at)
    if row is None:
        raise ValueError(f"input {inp.sensor!r}: a {inp.kind.value} input cannot act on the ground")
    nz = np.flatnonzero(np.abs(row) > _TOL)
    if inp.kind == InputKind.FLOOR and (len(nz) != 1 or abs(row[nz[0]] - 1.0) > _TOL):
        raise ValueError(f"input {inp.sensor!r}: a floor input prescribes one DOF, but {inp.at} is not on a DOF "
                         f"of model {model.name!r}")
    return int(nz[0])


def partition(model: AffineModel, theta: np.ndarray, inputs: Sequence[InputSpec]) -> Supports:
    """The supports, free DOFs and quasi-static influence of ``inputs`` on ``model`` at ``theta``."""
    n = model.n_dof
    K, M = model.stiffness(theta), model.mass(theta)
    support_dofs: list[int | None] = []
    input_support: list[int | None] = []
    loads: list[np.ndarray | None] = []
    for inp in inputs:
        if inp.kind == InputKind.FORCE:
            row = model.location_row(inp.at)
            if row is None:
                raise ValueError(f"input {inp.sensor!r}: a force cannot act on the ground")
            input_support.append(None)
            loads.append(row)
            continue
        dof = None if inp.kind == InputKind.BASE else _dof_of(model, inp)
        if inp.kind == InputKind.BASE and model.base_influence is None:
            raise ValueError(f"input {inp.sensor!r}: model {model.name!r} ({model.kind}) defines no ground "
                             "motion (base influence vector); give the input as kind floor or force")
        if dof in support_dofs:
            raise ValueError(f"input {inp.sensor!r}: its support is driven by another input already")
        input_support.append(len(support_dofs))
        support_dofs.append(dof)
        loads.append(None)
    prescribed = [d for d in support_dofs if d is not None]
    ground_moves = None in support_dofs
    ground_unknown = not ground_moves and bool(prescribed) and model.base_influence is not None
    r = np.zeros(n) if model.base_influence is None else np.asarray(model.base_influence, dtype=float)

    free = np.array([i for i in range(n) if i not in prescribed], dtype=int)
    if ground_unknown and free.size:
        free = _supported_part(model, K, M, free, r)
    known = np.zeros(n + 1, dtype=bool)
    known[free] = True
    known[prescribed] = True
    known[n] = not ground_unknown
    for k, ld in enumerate(loads):
        if ld is not None and np.any(np.abs(ld[~known[:n]]) > _TOL):
            raise ValueError(f"input {inputs[k].sensor!r}: the force acts where the inputs leave the motion "
                             "unknown (below the lowest floor input, with no base input)")
        if ld is not None and prescribed and np.any(np.abs(ld[prescribed]) > _TOL):
            raise ValueError(f"input {inputs[k].sensor!r}: the force acts on a DOF whose motion is prescribed")

    T = influence(model, K[None], free, support_dofs)[0]
    return Supports(free, support_dofs, input_support, loads, T, known, ground_moves)


def influence(model: AffineModel, K: np.ndarray, free: np.ndarray, support_dofs: Sequence[int | None]) -> np.ndarray:
    """``T`` of :class:`Supports` (B, n_dof + 1, n_supports) for stiffness matrices ``K`` (B, n, n):
    every node's quasi-static displacement per unit support displacement."""
    B, n = K.shape[0], model.n_dof
    r = np.zeros(n) if model.base_influence is None else np.asarray(model.base_influence, dtype=float)
    T = np.zeros((B, n + 1, len(support_dofs)))
    Kff = K[:, free][:, :, free]
    for s, dof in enumerate(support_dofs):
        if dof is None:
            T[:, n, s] = 1.0
            if free.size:
                T[:, free, s] = np.linalg.solve(Kff, (K @ r)[:, free, None])[..., 0]
        else:
            T[:, dof, s] = 1.0
            if free.size:
                T[:, free, s] = -np.linalg.solve(Kff, K[:, free, dof][..., None])[..., 0]
    return clean_rows(T.reshape(B, -1)).reshape(T.shape)


def clean_rows(v: np.ndarray) -> np.ndarray:
    """Zero the round-off of exact zeros in each row of ``v`` (B, m): entries below ``_TOL`` relative to
    the row's largest (at least 1), as of a rigid motion's extension computed through K^-1."""
    v = np.array(v, dtype=float)
    v[np.abs(v) < _TOL * np.maximum(1.0, np.max(np.abs(v), axis=-1, keepdims=True, initial=0.0))] = 0.0
    return v


def _supported_part(model: AffineModel, K: np.ndarray, M: np.ndarray, free: np.ndarray, r: np.ndarray
                    ) -> np.ndarray:
    """The free DOFs not coupled to the ground (whose motion is unknown) through other free DOFs."""
    sub = np.ix_(free, free)
    scale = max(float(np.max(np.abs(K))), 1e-300)
    adj = (np.abs(K[sub]) > _TOL * scale) | (M[sub] != 0)
    pos = {int(d): k for k, d in enumerate(free)}
    grounded = np.abs((K @ r)[free]) > _TOL * scale
    for d in model.dampers:
        i, j = d.nodes
        if i is None or j is None:
            other = j if i is None else i
            if other is not None and other in pos:
                grounded[pos[other]] = True
        elif i in pos and j in pos:
            adj[pos[i], pos[j]] = adj[pos[j], pos[i]] = True
    _, labels = connected_components(adj, directed=False)
    bad = set(labels[grounded].tolist())
    return free[[lab not in bad for lab in labels]]
