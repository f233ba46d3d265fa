"""JSON files of the pipeline (docs/interfaces.md section 3): one writer, one reader.

Every JSON output goes through :func:`dump` / :func:`dumps`, which accept numpy arrays and scalars,
tuples, paths, enums and dataclasses, and write strict JSON: a non-finite number (NaN, +-inf) is
written as ``null``, since JSON has no NaN and other readers reject the ``NaN`` token Python would
write. Mapping keys become strings.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
from collections.abc import Mapping
from pathlib import Path, PurePath
from typing import Any

import numpy as np

__all__ = ["to_jsonable", "dumps", "dump", "load", "loads"]


def to_jsonable(x: Any) -> Any:
    """``x`` as plain JSON types (dict, list, str, int, float, bool, None); TypeError naming the type
    of anything else."""
    if x is None or isinstance(x, (str, bool)):
        return x
    if isinstance(x, (int, np.integer)) and not isinstance(x, np.bool_):
        return int(x)
    if isinstance(x, (float, np.floating)):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, Mapping):
        return {str(k): to_jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [to_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        if x.dtype.kind in "iu":
            return x.tolist()
        if x.dtype.kind == "f":  # a trace of a million samples: no Python call per number
            finite = np.isfinite(x)
            if finite.all():
                return x.tolist()
            out = x.astype(object)
            out[~finite] = None
            return out.tolist()
        return to_jsonable(x.tolist())
    if isinstance(x, PurePath):
        return str(x)
    if isinstance(x, enum.Enum):
        return to_jsonable(x.value)
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return to_jsonable(dataclasses.asdict(x))
    if isinstance(x, (set, frozenset)):
        return [to_jsonable(v) for v in sorted(x, key=str)]
    raise TypeError(f"cannot write a {type(x).__name__} to JSON: {x!r}")


def dumps(obj: Any, indent: int | None = 1) -> str:
    """Strict JSON text of ``obj`` (see module doc)."""
    return json.dumps(to_jsonable(obj), indent=indent, allow_nan=False)


def dump(obj: Any, path: str | Path, indent: int | None = 1) -> Path:
    """Write ``obj`` as strict JSON to ``path`` (parent directories are created), atomically: the
    file appears complete or not at all."""
    from shm_ros.io.atomic import atomic_path

    p = Path(path)
    text = dumps(obj, indent) + "\n"
    with atomic_path(p) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return p


def loads(text: str) -> Any:
    return json.loads(text)


def load(path: str | Path) -> Any:
    """The JSON document in ``path`` (``null`` stays None: the writer's NaN)."""
    return json.loads(Path(path).read_text(encoding="utf-8"))
