"""Structure files (docs/interfaces.md section 2): YAML, plus an ``.npz`` for ``kind: matrices``.

``load_structure(path)`` reads and validates; ``dump_structure(spec, path)`` writes the same form
back (and the ``.npz`` of a matrices structure next to it). Every problem raises
:class:`~shm_ros.core.structure.StructureError` naming the file and the field.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import yaml

from shm_ros.core.models.registry import MODEL_KINDS, model_kind
from shm_ros.core.structure import StructureError, StructureSpec, structure_from_dict

__all__ = ["StructureError", "load_structure", "dump_structure", "load_matrices"]


class _UniqueKeyLoader(yaml.SafeLoader):
    """SafeLoader that refuses a key given twice in one mapping (PyYAML keeps the last silently)."""


def _construct_mapping(loader: _UniqueKeyLoader, node: yaml.MappingNode, deep: bool = False) -> dict:
    seen: set = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"key {key!r} appears twice in one mapping", key_node.start_mark
            )
        seen.add(key)
    return loader.construct_mapping(node, deep=deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def load_matrices(npz_path: str | Path, source: str, field_path: str = "matrices.file") -> dict[str, np.ndarray]:
    """All arrays of an ``.npz`` file as float arrays."""
    p = Path(npz_path)
    if not p.is_file():
        raise StructureError(f"matrix file {str(p)!r} not found", source, field_path)
    try:
        with np.load(p, allow_pickle=False) as z:
            return {k: np.asarray(z[k], dtype=float) for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise StructureError(f"cannot read matrix file {str(p)!r}: {exc}", source, field_path) from None


def load_structure(path: str | Path) -> StructureSpec:
    """Read and validate a structure YAML file; ``kind: matrices`` loads its ``.npz`` relative to it."""
    p = Path(path)
    source = str(p)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise StructureError("file not found", source) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise StructureError(f"cannot read file: {exc}", source) from None
    try:
        data = yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        raise StructureError(f"not valid YAML: {exc}", source) from None
    if not isinstance(data, dict):
        raise StructureError(f"must be a YAML mapping at the top level, got {type(data).__name__}", source)
    arrays = None
    kind = data.get("kind")
    fld = model_kind(kind).array_file_field if isinstance(kind, str) and kind in MODEL_KINDS else None
    section = data.get(kind) if fld else None
    if fld and isinstance(section, dict) and fld in section:
        f = section[fld]
        if not isinstance(f, str) or not f:
            raise StructureError(f"must be a file name, got {f!r}", source, f"{kind}.{fld}")
        npz = Path(f) if Path(f).is_absolute() else p.parent / f
        arrays = load_matrices(npz, source, f"{kind}.{fld}")
    return structure_from_dict(data, source=source, matrices_arrays=arrays)


def dump_structure(spec: StructureSpec, path: str | Path, write_matrices: bool = True) -> None:
    """Write ``spec`` as YAML; for a kind whose section names an ``.npz`` (``kind: matrices``) also
    that file (relative to the YAML)."""
    p = Path(path)
    data = spec.to_dict()
    fld = spec.model_kind.array_file_field
    p.write_text(
        f"# structure file of {spec.name} (shm_ros, docs/interfaces.md section 2)\n"
        + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=110),
        encoding="utf-8",
    )
    if write_matrices and fld and spec.arrays:
        f = Path(data[spec.kind][fld])
        npz = f if f.is_absolute() else p.parent / f
        np.savez(npz, **spec.arrays)  # type: ignore[arg-type]  # numpy types **kwds as allow_pickle
