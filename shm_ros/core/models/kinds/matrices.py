"""User matrices (``kind: matrices``): ``K = K0 + sum f_i K_i``, ``M = M + sum g_j M_j``.

Lets a user bring a model from any FE program: the ``.npz`` holds the mass matrix, the constant part
of the stiffness and one stiffness substructure matrix per term; ``matrices.terms`` gives each term's
nominal factor, and a parameter whose ``applies_to`` is ``matrices.terms.<name>`` multiplies it.

Structure-file section (docs/interfaces.md section 2)::

    matrices:
      file: model.npz        # relative to the structure file
      mass: M                # array names in the file (defaults M, K0)
      stiffness: K0
      terms: {K1: 1.0}       # default: every other K* array with factor 1
      mass_terms: {M1: 1.0}  # optional
      dofs: [...]            # optional DOF labels

Sensors sit at ``at: {dof: index | label}``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shm_ros.core.models.base import AffineModel, assemble_model, damping_factors_of
from shm_ros.core.models.registry import ModelKind, register
from shm_ros.core.structure import FieldReader, Location, StructureError, StructureSpec


@dataclass
class MatricesSpec:
    """User matrices: ``K = stiffness + sum factor_i * K_i``, ``M = mass + sum factor_j * M_j``.

    ``file`` is as written in the structure file (relative to it); ``arrays`` holds the loaded
    ``.npz`` contents (filled by ``shm_ros.io.structure.load_structure``). ``terms`` /
    ``mass_terms`` map array names to nominal factors (default 1.0 for every ``K<name>`` array other
    than the constant part). ``dofs`` optionally labels the DOFs.
    """

    file: str
    mass: str = "M"
    stiffness: str = "K0"
    terms: dict[str, float] = field(default_factory=dict)
    mass_terms: dict[str, float] = field(default_factory=dict)
    dofs: list[str] | None = None
    arrays: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    @property
    def n_dof(self) -> int:
        return int(self.arrays[self.mass].shape[0]) if self.mass in self.arrays else 0


@register("matrices")
class Matrices(ModelKind):
    title = "user matrices"
    array_file_field = "file"

    def parse_section(self, r: FieldReader, value: Any, arrays: Mapping[str, np.ndarray] | None) -> MatricesSpec:
        return _parse_matrices(r, value, arrays)

    def n_dof(self, section: MatricesSpec) -> int:
        return section.n_dof

    def section_to_dict(self, section: MatricesSpec) -> dict[str, Any]:
        m = section
        md: dict[str, Any] = {"file": m.file, "mass": m.mass, "stiffness": m.stiffness}
        md["terms"] = {k: float(v) for k, v in m.terms.items()}
        if m.mass_terms:
            md["mass_terms"] = {k: float(v) for k, v in m.mass_terms.items()}
        if m.dofs is not None:
            md["dofs"] = list(m.dofs)
        return md

    def sensor_location(self, r: FieldReader, section: MatricesSpec, at: Mapping[str, Any], direction: str,
                        fld: str) -> dict[str, Any]:
        r.keys(at, ("dof",), ("dof",), f"{fld}.at")
        d = at["dof"]
        if isinstance(d, str):
            if section.dofs is None or d not in section.dofs:
                raise r.err(f"DOF label {d!r} is not in matrices.dofs", f"{fld}.at.dof")
        else:
            d = r.integer(d, f"{fld}.at.dof", minimum=0)
            if d >= section.n_dof:
                raise r.err(f"DOF {d} does not exist (the matrices have {section.n_dof} DOFs)", f"{fld}.at.dof")
        return {"dof": d}

    def updatable(self, loc: Location) -> bool:
        return loc[:2] in (("matrices", "terms"), ("matrices", "mass_terms")) and len(loc) == 3

    def default_sensors(self, section: MatricesSpec) -> list[dict[str, Any]]:
        """One sensor per DOF (direction x: the matrices do not say which way a DOF points)."""
        labels: list[str | int] = list(section.dofs) if section.dofs is not None else list(range(section.n_dof))
        return [{"id": f"d{i}", "at": {"dof": d}, "direction": "x"} for i, d in enumerate(labels)]

    def build(self, spec: StructureSpec, **overrides: Any) -> AffineModel:
        """Overrides: ``include_parameters`` (:func:`build_matrices`)."""
        return build_matrices(spec, **overrides)


def _parse_matrices(r: FieldReader, v: Any, arrays: Mapping[str, np.ndarray] | None) -> MatricesSpec:
    m = r.mapping(v, "matrices")
    r.keys(m, ("file", "mass", "stiffness", "terms", "mass_terms", "dofs"), ("file",), "matrices")
    spec = MatricesSpec(
        file=r.string(m["file"], "matrices.file"),
        mass=r.string(m.get("mass", "M"), "matrices.mass"),
        stiffness=r.string(m.get("stiffness", "K0"), "matrices.stiffness"),
    )
    arrays = {k: np.asarray(a, dtype=float) for k, a in (arrays or {}).items()}
    if not arrays:
        raise r.err(
            f"no matrices loaded from {spec.file!r} (load the file with shm_ros.io.structure)", "matrices.file"
        )
    where = f"{spec.file}"
    for key in (spec.mass, spec.stiffness):
        if key not in arrays:
            fld = "matrices.mass" if key == spec.mass else "matrices.stiffness"
            raise r.err(f"array {key!r} not found in {where} (has {sorted(arrays)})", fld)
    n = arrays[spec.mass].shape[0] if arrays[spec.mass].ndim == 2 else -1
    if n == 0:
        raise r.err(f"mass matrix {spec.mass!r} in {where} is empty (no degree of freedom)", "matrices.mass")
    if "terms" in m:
        spec.terms = {
            str(k): r.number(f, f"matrices.terms.{k}") for k, f in r.mapping(m["terms"], "matrices.terms").items()
        }
    else:
        spec.terms = {k: 1.0 for k in sorted(arrays) if k.startswith("K") and k != spec.stiffness}
    if "mass_terms" in m:
        spec.mass_terms = {
            str(k): r.number(f, f"matrices.mass_terms.{k}")
            for k, f in r.mapping(m["mass_terms"], "matrices.mass_terms").items()
        }
    for key in [spec.mass, spec.stiffness, *spec.terms, *spec.mass_terms]:
        fld = "matrices.mass" if key == spec.mass else "matrices.stiffness" if key == spec.stiffness else (
            f"matrices.terms.{key}" if key in spec.terms else f"matrices.mass_terms.{key}"
        )
        if key not in arrays:
            raise r.err(f"array {key!r} not found in {where} (has {sorted(arrays)})", fld)
        a = arrays[key]
        if a.ndim != 2 or a.shape[0] != a.shape[1] or a.shape[0] != n:
            raise r.err(f"array {key!r} in {where} must be square {n}x{n}, got shape {a.shape}", fld)
        if not np.all(np.isfinite(a)):
            raise r.err(f"array {key!r} in {where} has non-finite entries", fld)
        if not np.allclose(a, a.T, rtol=1e-9, atol=1e-12 * max(1.0, float(np.abs(a).max()))):
            raise r.err(f"array {key!r} in {where} is not symmetric", fld)
    try:
        np.linalg.cholesky(arrays[spec.mass])
    except np.linalg.LinAlgError:
        raise r.err(
            f"mass matrix {spec.mass!r} in {where} is not positive definite (massless DOFs must be condensed "
            "out before export)",
            "matrices.mass",
        ) from None
    if "dofs" in m:
        dofs = [str(d) for d in r.seq(m["dofs"], "matrices.dofs")]
        if len(dofs) != n:
            raise r.err(f"has {len(dofs)} labels but the matrices have {n} DOFs", "matrices.dofs")
        spec.dofs = dofs
    spec.arrays = arrays
    return spec




def build_matrices(spec: StructureSpec, include_parameters: bool = True) -> AffineModel:
    """Affine model from the loaded ``.npz`` arrays of ``spec`` (kind ``matrices``)."""
    m = spec.section
    if not isinstance(m, MatricesSpec) or not m.arrays:
        raise StructureError("not a matrices structure with loaded arrays", spec.source, "matrices.file")
    params = spec.parameters if include_parameters else []
    n = m.n_dof
    K0 = np.array(m.arrays[m.stiffness], dtype=float)
    M0 = np.array(m.arrays[m.mass], dtype=float)
    K_terms = [np.zeros((n, n)) for _ in params]
    M_terms = [np.zeros((n, n)) for _ in params]
    owner: dict[tuple[str, str], int] = {}
    for i, p in enumerate(params):
        for loc in p.targets:
            if loc[0] == "matrices":
                owner[(str(loc[1]), str(loc[2]))] = i
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
                          damping_factors_of(params), kind="matrices")
