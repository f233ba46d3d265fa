"""User matrices (``kind: matrices``): ``K = K0 + sum f_i K_i``, ``M = M + sum g_j M_j``.

Lets a user bring a model from any FE program: the ``.npz`` holds the mass matrix, the constant part
of the stiffness and one stiffness substructure matrix per term; ``matrices.terms`` gives each term's
nominal factor, and a parameter whose ``applies_to`` is ``matrices.terms.<name>`` multiplies it.
"""

from __future__ import annotations

import numpy as np

from shm_ros.core.models.base import AffineModel, assemble_model
from shm_ros.core.structure import StructureError, StructureSpec


def build_matrices(spec: StructureSpec, include_parameters: bool = True) -> AffineModel:
    """Affine model from the loaded ``.npz`` arrays of ``spec`` (kind ``matrices``)."""
    m = spec.matrices
    if m is None or not m.arrays:
        raise StructureError("not a matrices structure with loaded arrays", spec.source, "matrices.file")
    params = spec.parameters if include_parameters else []
    n = m.n_dof
    K0 = np.array(m.arrays[m.stiffness], dtype=float)
    M0 = np.array(m.arrays[m.mass], dtype=float)
    K_terms = [np.zeros((n, n)) for _ in params]
    M_terms = [np.zeros((n, n)) for _ in params]
    owner: dict[tuple[str, str], int] = {}
    damping_factors: list[list[int]] = []
    for i, p in enumerate(params):
        dmp: list[int] = []
        for loc in p.targets:
            if loc[0] == "matrices":
                owner[(str(loc[1]), str(loc[2]))] = i
            elif loc[:2] == ("damping", "ratios"):
                dmp.append(int(loc[2]))
        damping_factors.append(dmp)
    for group, terms, base, dest in (("terms", m.terms, K0, K_terms), ("mass_terms", m.mass_terms, M0, M_terms)):
        for key, f in terms.items():
            i = owner.get((group, key), -1)
            if i < 0:
                base += f * m.arrays[key]
            else:
                dest[i] += f * m.arrays[key]
    labels = list(m.dofs) if m.dofs is not None else [f"dof{i}" for i in range(n)]
    sensor_dofs: dict[str, int] = {}
    for s in spec.sensors:
        d = s.at["dof"]
        sensor_dofs[s.id] = labels.index(d) if isinstance(d, str) else int(d)
    return assemble_model(spec, params, K0, M0, K_terms, M_terms, labels, sensor_dofs,
                          damping_factors, kind="matrices")
