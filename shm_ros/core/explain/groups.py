"""Parameter groups: named increments of the calibrated analysis model that candidates act on.

A group ``g`` is a pair ``(dK_g, dM_g)``; a factor ``x`` on it changes the calibrated baseline
model by ``K += (x - 1) dK_g``, ``M += (x - 1) dM_g``. For groups that exist in the baseline
(a span's bending stiffness, the bearings' vertical springs, a floor's mass) ``dK_g`` is that
group's own contribution, so ``x`` is the usual multiplicative factor. For groups the baseline does
not have (``bearings_rot``: a rotational restraint at pinned bearings; ``damper``: damper braces
as springs) ``dK_g`` is a reference restraint and the factor is additive: ``x - 1`` = restraint /
reference, ``x = 1`` is the baseline.

The groups are built by the structure kind's own model builder: the calibrated spec (the nominal
file with its parameters at the baseline MAP) is rewritten with one synthetic parameter per fine
group (``EI:k``, ``mass:k``, ...), so every group matrix is assembled exactly as the analysis model
assembles it. Coarse groups (``EI``, ``mass``) are sums of the fine ones.

girder: ``EI``, ``EI:k`` (span k, 1-based), ``bearings``, ``bearings_rot``, ``mass``, ``mass:k``.
shear_building: ``EI``, ``EI:k`` (story k), ``mass``, ``mass:k`` (floor k), ``damper`` (when the file
has ``dampers:``). A base spring (foundation) changes the model's DOFs and is not a group here.
matrices (a user's model, e.g. imported from OpenSees): ``EI:<term>`` per stiffness term of the file
(``matrices.terms``), ``EI`` their sum (the whole stiffness when the file has no terms), ``mass``
(the whole mass) and ``mass:<term>`` per mass term.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shm_ros.core.models import build_model
from shm_ros.core.models.base import AffineModel
from shm_ros.core.structure import StructureSpec, structure_from_dict

# reference rotational restraint of a bearing: 4 EI / L of the shortest span adjacent to it (the
# rotational stiffness a span offers with its far end fixed), so x - 1 = 1 is a stiff restraint
ROTATION_REFERENCE = 4.0
# reference damper-brace stiffness when a damper gives no k_maxwell: this share of the story's stiffness
# (1: the factor x - 1 is the brace stiffness in units of the story stiffness, and a lost brace
# stiffness of the calibrated model is a factor in (0, 1), which the surrogate tabulates in ln x)
DAMPER_REFERENCE = 1.0
_DUMMY_PRIOR = {"dist": "normal", "mean": 1.0, "std": 0.1}


@dataclass
class Group:
    """One group: its increments (n, n), whether its factor is additive, and its plain name."""

    name: str
    dK: np.ndarray
    dM: np.ndarray
    additive: bool = False  # baseline has none of it: x - 1 = amount / reference
    title: str = ""


@dataclass
class GroupModel:
    """The calibrated baseline ``(K, M)`` and its groups; matrices of any group factors."""

    K: np.ndarray
    M: np.ndarray
    groups: dict[str, Group]
    model: AffineModel  # the builder's model of the group spec (sensors, DOF labels)
    fine: dict[str, list[str]] = field(default_factory=dict)  # coarse group -> its fine groups

    def names(self) -> list[str]:
        return list(self.groups)

    def matrices(self, factors: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """K, M (N, n, n) for factors {group: (N,)} (groups not named stay at 1)."""
        n_b = len(next(iter(factors.values()))) if factors else 1
        K = np.broadcast_to(self.K, (n_b, *self.K.shape)).copy()
        M = np.broadcast_to(self.M, (n_b, *self.M.shape)).copy()
        for g, x in factors.items():
            grp = self.groups[g]
            d = (np.asarray(x, dtype=float) - 1.0)[:, None, None]
            K += d * grp.dK
            M += d * grp.dM
        return K, M


def calibrated_spec(spec: StructureSpec, theta: dict[str, float]) -> StructureSpec:
    """The structure with its parameters' values at ``theta`` (the factors applied, no parameters)."""
    scaled = spec.scaled({k: v for k, v in theta.items() if k in {p.name for p in spec.parameters}})
    data = scaled.to_dict()
    data.pop("parameters", None)
    return structure_from_dict(data, source=spec.source, matrices_arrays=spec.arrays)


def build_groups(spec: StructureSpec, theta: dict[str, float] | None = None) -> GroupModel:
    """The groups of ``spec``'s kind around the calibrated model (parameters at ``theta``)."""
    base = calibrated_spec(spec, theta or {})
    if base.kind == "girder":
        return _girder(base)
    if base.kind == "shear_building":
        return _shear_building(base)
    if base.kind == "matrices":
        return _matrices(base)
    raise ValueError(f"explain: no parameter groups for structure kind {base.kind!r} "
                     "(girder, shear_building, matrices)")


def _assemble(data: dict[str, Any], fine: list[tuple[str, str, bool, str]], source: str
              ) -> tuple[AffineModel, dict[str, Group], np.ndarray, np.ndarray]:
    data["parameters"] = [{"name": n, "applies_to": path, "prior": dict(_DUMMY_PRIOR)} for n, path, _, _ in fine]
    model = build_model(structure_from_dict(data, source=source))
    z = np.zeros_like(model.K0)
    groups: dict[str, Group] = {}
    K, M = model.K0.copy(), model.M0.copy()
    for i, (n, _, additive, title) in enumerate(fine):
        dK = z if model.K_terms[i] is None else model.K_terms[i]
        dM = z if model.M_terms[i] is None else model.M_terms[i]
        groups[n] = Group(n, np.asarray(dK), np.asarray(dM), additive, title)
        if not additive:
            K += groups[n].dK
            M += groups[n].dM
    return model, groups, K, M


def _sum_group(name: str, parts: list[Group], title: str) -> Group:
    return Group(name, sum((p.dK for p in parts), np.zeros_like(parts[0].dK)),
                 sum((p.dM for p in parts), np.zeros_like(parts[0].dM)), parts[0].additive, title)


def _girder(spec: StructureSpec) -> GroupModel:
    data = copy.deepcopy(spec.to_dict())
    g = data["girder"]
    n_spans = len(g["spans"])
    sec = g["section"]
    g["section"] = [copy.deepcopy(sec) for _ in range(n_spans)] if isinstance(sec, dict) else sec
    ends = np.concatenate([[0.0], np.cumsum(g["spans"])])
    for b in g["bearings"]:  # the reference restraint (the baseline keeps its own k_rotation in K0)
        near = [k for k in range(n_spans) if ends[k] - 1e-9 <= b["x"] <= ends[k + 1] + 1e-9]
        ei_over_l = max(g["section"][k]["E"] * g["section"][k]["I"] / g["spans"][k] for k in near)
        b["k_rotation_ref"] = ROTATION_REFERENCE * ei_over_l
    k_rot_base = [float(b.get("k_rotation", 0.0)) for b in g["bearings"]]
    for b in g["bearings"]:
        b["k_rotation"] = b.pop("k_rotation_ref")
    fine = [(f"EI:{k + 1}", f"girder.section[{k}].E", False, f"bending stiffness of span {k + 1}")
            for k in range(n_spans)]
    fine += [(f"mass:{k + 1}", f"girder.section[{k}].rho", False, f"mass of span {k + 1}") for k in range(n_spans)]
    fine += [("bearings", "girder.bearings[*].k_vertical", False, "vertical bearing springs"),
             ("bearings_rot", "girder.bearings[*].k_rotation", True, "rotational restraint at the bearings")]
    model, groups, K, M = _assemble(data, fine, spec.source)
    # the baseline's own rotational restraint (usually none) is part of the baseline
    ref = [float(b["k_rotation"]) for b in g["bearings"]]
    if any(v > 0 for v in k_rot_base):
        scale = np.mean([kb / r for kb, r in zip(k_rot_base, ref, strict=True)])
        K = K + scale * groups["bearings_rot"].dK
    groups["EI"] = _sum_group("EI", [groups[f"EI:{k + 1}"] for k in range(n_spans)], "bending stiffness of the deck")
    groups["mass"] = _sum_group("mass", [groups[f"mass:{k + 1}"] for k in range(n_spans)], "mass of the deck")
    return GroupModel(K, M, groups, model, {"EI": [f"EI:{k + 1}" for k in range(n_spans)],
                                            "mass": [f"mass:{k + 1}" for k in range(n_spans)]})


def _shear_building(spec: StructureSpec) -> GroupModel:
    data = copy.deepcopy(spec.to_dict())
    floors = data["shear_building"]["floors"]
    n = len(floors)
    fine = [(f"EI:{k + 1}", f"shear_building.floors[{k}].stiffness", False, f"stiffness of story {k + 1}")
            for k in range(n)]
    fine += [(f"mass:{k + 1}", f"shear_building.floors[{k}].mass", False, f"mass of floor {k + 1}") for k in range(n)]
    model, groups, K, M = _assemble(data, fine, spec.source)
    groups["EI"] = _sum_group("EI", [groups[f"EI:{k + 1}"] for k in range(n)], "stiffness of every story")
    groups["mass"] = _sum_group("mass", [groups[f"mass:{k + 1}"] for k in range(n)], "every floor mass")
    coarse = {"EI": [f"EI:{k + 1}" for k in range(n)], "mass": [f"mass:{k + 1}" for k in range(n)]}
    dampers = data["shear_building"].get("dampers") or []
    if dampers:
        dK = np.zeros_like(K)
        for d in dampers:
            i, j = d["between"]
            k_ref = d.get("k_maxwell") or DAMPER_REFERENCE * floors[max(i, j) - 1]["stiffness"]
            b = np.zeros(n)
            if i > 0:
                b[i - 1] += 1.0
            if j > 0:
                b[j - 1] -= 1.0
            dK += float(k_ref) * np.outer(b, b)
        groups["damper"] = Group("damper", dK, np.zeros_like(M), True, "damper braces as springs")
    return GroupModel(K, M, groups, model, coarse)


def _matrices(spec: StructureSpec) -> GroupModel:
    """Groups of a user's matrices: each term as the calibrated file scales it (factor 1 = the file)."""
    model = build_model(spec)
    m = spec.section
    arrays: dict[str, np.ndarray] = m.arrays
    K, M = model.K0.copy(), model.M0.copy()
    z = np.zeros_like(K)
    groups = {f"EI:{t}": Group(f"EI:{t}", f * arrays[t], z, False, f"stiffness term {t}")
              for t, f in m.terms.items()}
    groups |= {f"mass:{t}": Group(f"mass:{t}", z, f * arrays[t], False, f"mass term {t}")
               for t, f in m.mass_terms.items()}
    stiff = [g for g in groups.values() if g.name.startswith("EI:")]
    groups["EI"] = _sum_group("EI", stiff, "every stiffness term") if stiff else Group(
        "EI", K.copy(), z, False, "the whole stiffness")
    groups["mass"] = Group("mass", z, M.copy(), False, "the whole mass")
    return GroupModel(K, M, groups, model, {"EI": [g.name for g in stiff],
                                            "mass": [n for n in groups if n.startswith("mass:")]})
