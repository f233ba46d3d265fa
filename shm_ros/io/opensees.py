"""A structure file from a user's OpenSeesPy model (``shm-ros import opensees``).

The user's script builds an elastic model with ``openseespy.opensees`` and declares, with OpenSees's
own ``parameter`` / ``addToParameter`` commands, the quantities to update (an ``E`` of some elements,
the ``material 1 E`` of some bearing springs, ...). It runs once, in this process, at the user's
explicit command. Then OpenSees itself assembles the matrices (``GimmeMCK`` integrator, full
system, plain numbering): the mass M, the stiffness K at the script's values, and for each
parameter the stiffness with that parameter doubled, so ``K_i = K(2 p_i) - K(p_i)`` is the
parameter's nominal part of K and ``K0 = K - sum K_i`` the rest; a third point (``0.5 p_i``) checks
that K is linear in it and that M does not depend on it. The lowest modes of (K, M) are checked
against OpenSees's own ``eigen``; the result is a ``kind: matrices`` structure file (YAML + ``.npz``,
docs/structure_files.md) that every stage reads unchanged.

OpenSeesPy is an optional extra (``pip install "shm_ros[opensees]"``; its licence is not the
project's); nothing else imports it.
"""

from __future__ import annotations

import runpy
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy.linalg import eigh

from shm_ros.errors import InputError, NumericalFailure

EIGEN_RTOL = 1e-6  # frequencies of the written matrices vs OpenSees's eigen
LINEAR_RTOL = 1e-8  # K(0.5 p) vs K(p) - 0.5 K_i, relative to the largest entry of K


class OpenSeesImportError(InputError):
    """The script, a parameter or a sensor cannot be turned into a structure file."""


@dataclass(frozen=True)
class Sensor:
    id: str
    node: int
    dof: int  # 1-based, as in OpenSees


@dataclass
class OpenSeesMatrices:
    M: np.ndarray
    K0: np.ndarray
    terms: dict[str, np.ndarray]  # parameter name -> its nominal part of K
    dof_labels: list[str]  # "n<node>:<dof>" of every equation
    opensees_hz: np.ndarray  # OpenSees's eigen, lowest modes
    matrices_hz: np.ndarray  # the same modes of (K0 + sum K_i, M)


def parse_parameters(text: str) -> dict[str, int]:
    """``"E_scale=1,k_bearing=2"`` -> {name: OpenSees parameter tag}."""
    out: dict[str, int] = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        name, _, tag = item.partition("=")
        if not name.strip() or not tag.strip().isdigit():
            raise OpenSeesImportError(f"--parameters: expected NAME=TAG (an OpenSees parameter tag), got {item!r}")
        out[name.strip()] = int(tag)
    if not out:
        raise OpenSeesImportError("--parameters: name at least one OpenSees parameter, e.g. E_scale=1")
    return out


def parse_sensors(text: str) -> list[Sensor]:
    """``"s1=5:2,s2=9:2"`` -> sensors at (node, 1-based DOF)."""
    out = []
    for item in filter(None, (s.strip() for s in text.split(","))):
        sid, _, where = item.partition("=")
        node, _, dof = where.partition(":")
        if not sid.strip() or not node.strip().isdigit() or not dof.strip().isdigit():
            raise OpenSeesImportError(f"--sensors: expected ID=NODE:DOF, got {item!r}")
        out.append(Sensor(sid.strip(), int(node), int(dof)))
    if not out:
        raise OpenSeesImportError("--sensors: name at least one sensor, e.g. s1=5:2")
    return out


def _ops() -> Any:
    try:
        import openseespy.opensees as ops
    except ImportError as exc:
        raise OpenSeesImportError('OpenSeesPy is not installed: pip install "openseespy<3.8" (on Debian also '
                                  f"libblas3 liblapack3) ({exc})") from None
    return ops


def _matrix(ops: Any, m: float, k: float) -> np.ndarray:
    """OpenSees's assembled m M + k K (equations of the free DOFs, plain numbering)."""
    ops.wipeAnalysis()
    ops.system("FullGeneral")
    ops.numberer("Plain")
    ops.constraints("Plain")
    ops.algorithm("Linear")
    ops.integrator("GimmeMCK", m, 0.0, k)
    ops.analysis("Transient")
    ops.analyze(1, 0.0)
    n = int(ops.systemSize())
    return np.array(ops.printA("-ret"), dtype=float).reshape(n, n)


def _dof_labels(ops: Any, n: int) -> list[str]:
    labels = [""] * n
    for node in ops.getNodeTags():
        for j, eq in enumerate(ops.nodeDOFs(node)):
            if 0 <= eq < n:
                labels[eq] = f"n{node}:{j + 1}"
    if not all(labels):
        raise OpenSeesImportError("some equations belong to no node DOF (constraints other than fix are not "
                                  "supported: use fix, or model the constraint with stiff elements)")
    return labels


def _parameter_term(ops: Any, name: str, tag: int, K: np.ndarray, M: np.ndarray) -> np.ndarray:
    """The parameter's nominal part of K; checks linearity and that M does not move."""
    try:
        p0 = float(ops.getParamValue(tag))
    except Exception as exc:  # OpenSeesPy raises its own error type for an unknown tag
        raise OpenSeesImportError(f"parameter {name!r}: the script defines no OpenSees parameter {tag} "
                                  f"({exc})") from None
    if p0 == 0:
        raise OpenSeesImportError(f"parameter {name!r} (OpenSees parameter {tag}) is 0 in the script")
    try:
        ops.updateParameter(tag, 2.0 * p0)
        K_up, M_up = _matrix(ops, 0.0, 1.0), _matrix(ops, 1.0, 0.0)
        ops.updateParameter(tag, 0.5 * p0)
        K_half = _matrix(ops, 0.0, 1.0)
    finally:
        ops.updateParameter(tag, p0)
    term = K_up - K
    scale = float(np.max(np.abs(K)))
    if not np.any(term):
        raise OpenSeesImportError(f"parameter {name!r} (OpenSees parameter {tag}) does not change the stiffness")
    if np.max(np.abs(K_half - (K - 0.5 * term))) > LINEAR_RTOL * scale:
        raise OpenSeesImportError(f"the stiffness is not linear in parameter {name!r} (OpenSees parameter {tag}); "
                                  "only parameters K is proportional to (E, I, A of elastic elements, spring "
                                  "stiffnesses) can be updated")
    if np.max(np.abs(M_up - M)) > LINEAR_RTOL * float(np.max(np.abs(M))):
        raise OpenSeesImportError(f"parameter {name!r} (OpenSees parameter {tag}) changes the mass; only "
                                  "stiffness parameters can be imported")
    return 0.5 * (term + term.T)


def extract(ops: Any, parameters: dict[str, int], n_modes: int = 5) -> OpenSeesMatrices:
    """Matrices of the model the script built (see module docstring), checked against ``eigen``."""
    K, M = _matrix(ops, 0.0, 1.0), _matrix(ops, 1.0, 0.0)
    labels = _dof_labels(ops, K.shape[0])
    terms = {name: _parameter_term(ops, name, tag, K, M) for name, tag in parameters.items()}
    K, M = 0.5 * (K + K.T), 0.5 * (M + M.T)
    K0 = K - sum(terms.values())
    n = min(n_modes, K.shape[0] - 1)
    ops.wipeAnalysis()
    lam = np.asarray(ops.eigen(n), dtype=float)
    w = eigh(K0 + sum(terms.values()), M, eigvals_only=True, subset_by_index=(0, n - 1))
    ref = np.sqrt(np.clip(lam, 0, None)) / (2 * np.pi)
    got = np.sqrt(np.clip(w, 0, None)) / (2 * np.pi)
    if np.max(np.abs(got / ref - 1)) > EIGEN_RTOL:
        raise NumericalFailure(f"the assembled matrices do not reproduce OpenSees's eigen: {got} Hz vs {ref} Hz")
    return OpenSeesMatrices(M, K0, terms, labels, ref, got)


def structure_dict(name: str, mats: OpenSeesMatrices, npz_name: str, sensors: list[Sensor], direction: str,
                   prior_std: float, damping: list[float]) -> dict[str, Any]:
    """The ``kind: matrices`` structure file's content."""
    missing = [s for s in sensors if f"n{s.node}:{s.dof}" not in mats.dof_labels]
    if missing:
        raise OpenSeesImportError(f"sensor(s) {[s.id for s in missing]} sit on no free DOF of the model "
                                  "(a missing node, or a fixed DOF)")
    return {
        "name": name,
        "kind": "matrices",
        "description": "imported from an OpenSeesPy script by shm-ros import opensees",
        "matrices": {"file": npz_name, "mass": "M", "stiffness": "K0",
                     "terms": {f"K_{p}": 1.0 for p in mats.terms}, "dofs": list(mats.dof_labels)},
        "damping": {"kind": "rayleigh", "ratios": [float(z) for z in damping]},
        "sensors": [{"id": s.id, "at": {"dof": f"n{s.node}:{s.dof}"}, "direction": direction} for s in sensors],
        "parameters": [{"name": p, "applies_to": f"matrices.terms.K_{p}",
                        "prior": {"dist": "lognormal", "mean": 1.0, "std": float(prior_std)}} for p in mats.terms],
    }


def import_opensees(script: str | Path, parameters: dict[str, int], sensors: list[Sensor], out: str | Path, *,
                    name: str | None = None, direction: str = "vertical", prior_std: float = 0.1,
                    damping: tuple[float, float] = (0.02, 0.02), n_modes: int = 5) -> OpenSeesMatrices:
    """Run ``script`` once, write ``out`` (YAML) and its ``.npz`` next to it; returns the matrices."""
    script, out = Path(script), Path(out)
    if not script.is_file():
        raise OpenSeesImportError(f"{script}: OpenSees script not found")
    ops = _ops()
    ops.wipe()
    try:
        runpy.run_path(str(script), run_name="__main__")
    except SystemExit as exc:
        raise OpenSeesImportError(f"{script}: the script exited ({exc.code})") from None
    mats = extract(ops, parameters, n_modes)
    npz = out.with_suffix(".npz")
    data = structure_dict(name or script.stem, mats, npz.name, sensors, direction, prior_std, list(damping))
    out.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, np.ndarray] = {"M": mats.M, "K0": mats.K0, **{f"K_{p}": k for p, k in mats.terms.items()}}
    np.savez(npz, **arrays)  # type: ignore[arg-type]  # numpy's stub types the keyword arrays as allow_pickle
    out.write_text(f"# structure file made by shm-ros import opensees from {script.name}\n"
                   + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=110), encoding="utf-8")
    ops.wipe()
    return mats
