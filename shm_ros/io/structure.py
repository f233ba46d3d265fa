"""Structure files (docs/interfaces.md section 2): YAML, plus an ``.npz`` for ``kind: matrices``.

``load_structure(path)`` reads and validates; ``dump_structure(spec, path)`` writes the same form
back (and the ``.npz`` of a matrices structure next to it). Every problem raises
:class:`~shm_ros.core.structure.StructureError` naming the file and the field.

A structure file may come from anyone, so reading one is bounded (:class:`StructureLimits`): the
file's size, the number of YAML nodes after aliases are expanded (an "alias bomb" of a few lines
names billions), the model's degrees of freedom (checked from the section and from the ``.npz``
headers before any array is read), and a file the structure names (``matrices.file``) must lie in
the structure file's folder. The limits are raised by the caller (``limits=``) or the environment:
``SHM_ROS_MAX_DOF``, ``SHM_ROS_STRUCTURE_MAX_BYTES`` and ``SHM_ROS_STRUCTURE_PATHS=anywhere`` -
never by the file itself. Numbers are read as YAML 1.2 writes them (``5e9`` is a number, not the
text PyYAML's YAML 1.1 rules make of it); a field that needs a number refuses text and booleans.
"""

from __future__ import annotations

import math
import os
import re
import tokenize
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from shm_ros.core.models.registry import MODEL_KINDS, model_kind
from shm_ros.core.structure import DEFAULT_MAX_DOF, StructureError, StructureSpec, structure_from_dict
from shm_ros.io.atomic import atomic_path

__all__ = ["StructureError", "StructureLimits", "load_structure", "dump_structure", "load_matrices", "read_yaml"]


def _env_int(name: str, default: int) -> int:
    text = os.environ.get(name, "").strip()
    if not text:
        return default
    try:
        value = int(text)
    except ValueError:
        raise StructureError(f"environment variable {name}={text!r} is not an integer") from None
    if value < 1:
        raise StructureError(f"environment variable {name}={text!r} must be >= 1")
    return value


@dataclass(frozen=True)
class StructureLimits:
    """Bounds on reading one structure file (module docstring); defaults from the environment."""

    max_bytes: int = field(default_factory=lambda: _env_int("SHM_ROS_STRUCTURE_MAX_BYTES", 4 * 2**20))
    max_nodes: int = 1_000_000  # YAML nodes after alias expansion
    max_dof: int = field(default_factory=lambda: _env_int("SHM_ROS_MAX_DOF", DEFAULT_MAX_DOF))
    max_arrays: int = 1000  # arrays in a matrices .npz
    paths_anywhere: bool = field(
        default_factory=lambda: os.environ.get("SHM_ROS_STRUCTURE_PATHS", "").strip().lower() == "anywhere")


_SafeBase: type = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml's parser when built with it


class _UniqueKeyLoader(_SafeBase):
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
# YAML 1.2 floats: ``5e9``, ``1.5E-3`` (YAML 1.1 needs a dot and a signed exponent, else it is text)
_UniqueKeyLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"), list("-+0123456789"))


def _expanded_nodes(root: yaml.Node, limit: int, source: str) -> int:
    """Nodes of the composed document with every alias expanded, counted without expanding (a node
    reached through several aliases counts each time); StructureError above ``limit`` or when an
    alias refers to a node that contains it."""
    memo: dict[int, int] = {}
    visiting: set[int] = set()
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, done = stack.pop()
        key = id(node)
        if key in memo:
            continue
        children: list[yaml.Node] = []
        if isinstance(node, yaml.SequenceNode):
            children = list(node.value)
        elif isinstance(node, yaml.MappingNode):
            children = [n for kv in node.value for n in kv]
        if done:
            visiting.discard(key)
            memo[key] = 1 + sum(memo[id(c)] for c in children)
            if memo[key] > limit:
                raise StructureError(f"the YAML expands to more than {limit} nodes (aliases of aliases?); "
                                     "refused", source)
            continue
        if key in visiting:
            raise StructureError("an alias refers to a node that contains it; refused", source)
        visiting.add(key)
        stack.append((node, True))
        stack.extend((c, False) for c in children if id(c) not in memo)
    return memo[id(root)]


def read_yaml(text: str, source: str, limits: StructureLimits | None = None):
    """Parse YAML text safely (no tags beyond the standard ones, unique keys, YAML 1.2 numbers) and
    bounded (size, expanded node count): for structure files and other user YAML."""
    limits = limits or StructureLimits()
    if len(text) > limits.max_bytes:
        raise StructureError(f"file is {len(text)} bytes, more than the limit of {limits.max_bytes} "
                             "(SHM_ROS_STRUCTURE_MAX_BYTES)", source)
    try:
        loader = _UniqueKeyLoader(text)
        try:
            node = loader.get_single_node()
            if node is None:
                return None
            _expanded_nodes(node, limits.max_nodes, source)
            return loader.construct_document(node)
        finally:
            loader.dispose()
    except yaml.YAMLError as exc:
        raise StructureError(f"not valid YAML: {exc}", source) from None
    except RecursionError:
        raise StructureError("the YAML nests too deeply", source) from None


def _npz_shapes(z: zipfile.ZipFile, p: Path, source: str, field_path: str
                ) -> dict[str, tuple[tuple[int, ...], bool]]:
    """Each array's shape from its ``.npy`` header, read before any data, and whether the member
    holds the data the header announces."""
    shapes: dict[str, tuple[tuple[int, ...], bool]] = {}
    for name in z.namelist():
        if not name.endswith(".npy"):
            continue
        with z.open(name) as fh:
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
            else:
                shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
            header = fh.tell()
        if dtype.hasobject:
            raise StructureError(f"array {name[:-4]!r} in {str(p)!r} holds Python objects; refused", source,
                                 field_path)
        shapes[name[:-4]] = (tuple(int(n) for n in shape),
                             math.prod(shape) * dtype.itemsize <= z.getinfo(name).file_size - header)
    return shapes


def load_matrices(npz_path: str | Path, source: str, field_path: str = "matrices.file",
                  limits: StructureLimits | None = None) -> dict[str, np.ndarray]:
    """All arrays of an ``.npz`` file as float arrays; an array larger than ``limits.max_dof`` along
    any axis is refused from its header, before it is read."""
    limits = limits or StructureLimits()
    p = Path(npz_path)
    if not p.is_file():
        raise StructureError(f"matrix file {str(p)!r} not found", source, field_path)
    try:
        with zipfile.ZipFile(p) as zf:
            shapes = _npz_shapes(zf, p, source, field_path)
        if len(shapes) > limits.max_arrays:
            raise StructureError(f"{str(p)!r} holds {len(shapes)} arrays, more than {limits.max_arrays}", source,
                                 field_path)
        for name, (shape, fits) in shapes.items():
            if any(n > limits.max_dof for n in shape) or len(shape) > 2:
                raise StructureError(
                    f"array {name!r} in {str(p)!r} has shape {shape}: more than the limit of {limits.max_dof} "
                    "degrees of freedom (raise it with SHM_ROS_MAX_DOF)", source, field_path)
            if not fits:
                raise StructureError(f"array {name!r} in {str(p)!r}: its header announces more data than the "
                                     "file holds", source, field_path)
        with np.load(p, allow_pickle=False) as z:
            return {k: np.asarray(z[k], dtype=float) for k in z.files}
    except StructureError:
        raise
    except (OSError, ValueError, EOFError, SyntaxError, tokenize.TokenError, UnicodeDecodeError, TypeError,
            zipfile.BadZipFile, zipfile.LargeZipFile, NotImplementedError, zlib.error) as exc:
        raise StructureError(f"cannot read matrix file {str(p)!r}: {exc}", source, field_path) from None


def load_structure(path: str | Path, limits: StructureLimits | None = None) -> StructureSpec:
    """Read and validate a structure YAML file; ``kind: matrices`` loads its ``.npz`` relative to it.
    ``limits``: the bounds of the module docstring (default: :class:`StructureLimits` ())."""
    limits = limits or StructureLimits()
    p = Path(path)
    source = str(p)
    try:
        size = p.stat().st_size
        if size > limits.max_bytes:
            raise StructureError(f"file is {size} bytes, more than the limit of {limits.max_bytes} "
                                 "(SHM_ROS_STRUCTURE_MAX_BYTES)", source)
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise StructureError("file not found", source) from None
    except IsADirectoryError:
        raise StructureError("is a directory, not a structure file", source) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise StructureError(f"cannot read file: {exc}", source) from None
    data = read_yaml(text, source, limits)
    if not isinstance(data, dict):
        raise StructureError(f"must be a YAML mapping at the top level, got {type(data).__name__}", source)
    arrays = None
    kind = data.get("kind")
    fld = model_kind(kind).array_file_field if isinstance(kind, str) and kind in MODEL_KINDS else None
    section = data.get(kind) if fld else None
    if fld and isinstance(section, dict) and fld in section:
        f = section[fld]
        if not isinstance(f, str) or not f:
            raise StructureError(f"must be a file name, got {str(f)[:80]!r}", source, f"{kind}.{fld}")
        npz = Path(f) if Path(f).is_absolute() else p.parent / f
        if not limits.paths_anywhere:
            folder = p.parent.resolve()
            if not npz.resolve().is_relative_to(folder):
                raise StructureError(f"{f!r} lies outside the structure file's folder {str(folder)!r}; refused "
                                     "(allow with SHM_ROS_STRUCTURE_PATHS=anywhere)", source, f"{kind}.{fld}")
        arrays = load_matrices(npz, source, f"{kind}.{fld}", limits)
    return structure_from_dict(data, source=source, matrices_arrays=arrays, max_dof=limits.max_dof)


def dump_structure(spec: StructureSpec, path: str | Path, write_matrices: bool = True) -> None:
    """Write ``spec`` as YAML; for a kind whose section names an ``.npz`` (``kind: matrices``) also
    that file (relative to the YAML)."""
    p = Path(path)
    data = spec.to_dict()
    fld = spec.model_kind.array_file_field
    with atomic_path(p) as tmp:
        tmp.write_text(
            f"# structure file of {spec.name} (shm_ros, docs/interfaces.md section 2)\n"
            + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=110),
            encoding="utf-8",
        )
    if write_matrices and fld and spec.arrays:
        f = Path(data[spec.kind][fld])
        npz = f if f.is_absolute() else p.parent / f
        with atomic_path(npz) as tmp, open(tmp, "wb") as fh:
            np.savez(fh, **spec.arrays)  # type: ignore[arg-type]  # numpy types **kwds as allow_pickle
