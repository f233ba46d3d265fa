"""A typed, data-only encoding of in-memory state (the tracker's checkpoint in the history store).

Reading a file must never run code, so nothing read from disk is unpickled. :func:`encode` turns a
value into JSON built from a closed set of shapes, and :func:`decode` turns it back:

* ``None``, ``bool``, ``int``, ``str`` and finite floats as themselves; a non-finite float as
  ``{"f": "nan" | "inf" | "-inf"}``;
* ``{"t": [...]}`` a tuple, ``{"l": [...]}`` a list, ``{"q": [...], "n": maxlen}`` a deque,
  ``{"d": [[key, value], ...]}`` a dict (any keys the encoding covers);
* ``{"a": dtype, "s": shape, "b": base64}`` a numpy array of a numeric or boolean dtype (never an
  object array);
* ``{"e": name, "v": value}`` a member of an allowed enum, ``{"o": name, "s": {...}}`` an instance
  of an allowed class, rebuilt without calling its ``__init__`` (its attributes are set from the
  decoded mapping).

Classes and enums are named by ``module:qualname`` and looked up in the caller's allow-list only:
an unknown name, shape or dtype raises :class:`CheckpointError`, so a crafted file can at worst be
refused. Encoding an object whose class is not allowed raises ``TypeError`` (a programming error).
"""

from __future__ import annotations

import base64
import json
import math
from collections import deque
from collections.abc import Iterable
from enum import Enum
from typing import Any

import numpy as np

from shm_ros.errors import InputError

__all__ = ["CheckpointError", "Codec"]

MAX_DEPTH = 64
_DTYPES = frozenset("?bBhHiIlLqQefdgFD")  # numeric and boolean numpy type characters


class CheckpointError(InputError):
    """A checkpoint that does not decode to the allowed types; the message says why."""


def _name(cls: type) -> str:
    return f"{cls.__module__}:{cls.__qualname__}"


class Codec:
    """Encoder/decoder over an allow-list of classes (plain attribute objects, dataclasses) and enums."""

    def __init__(self, classes: Iterable[type]) -> None:
        self.classes = {_name(c): c for c in classes}

    # -- encoding ----------------------------------------------------------------------------------
    def dumps(self, value: Any) -> bytes:
        return json.dumps(self.encode(value), separators=(",", ":"), allow_nan=False).encode()

    def encode(self, v: Any, depth: int = 0) -> Any:
        if depth > MAX_DEPTH:
            raise TypeError("checkpoint: state nested too deeply")
        d = depth + 1
        if v is None or isinstance(v, (bool, str)):
            return v
        if isinstance(v, Enum):
            if _name(type(v)) not in self.classes:
                raise TypeError(f"checkpoint: enum {_name(type(v))} is not allowed")
            return {"e": _name(type(v)), "v": self.encode(v.value, d)}
        if isinstance(v, (int, np.integer)) and not isinstance(v, np.bool_):
            return int(v)
        if isinstance(v, (float, np.floating)):
            x = float(v)
            return x if math.isfinite(x) else {"f": "nan" if x != x else ("inf" if x > 0 else "-inf")}
        if isinstance(v, np.bool_):
            return bool(v)
        if isinstance(v, np.ndarray):
            if v.dtype.char not in _DTYPES:
                raise TypeError(f"checkpoint: array dtype {v.dtype} is not allowed")
            a = np.ascontiguousarray(v)
            return {"a": a.dtype.str, "s": list(a.shape), "b": base64.b64encode(a.tobytes()).decode()}
        if isinstance(v, tuple):
            return {"t": [self.encode(x, d) for x in v]}
        if isinstance(v, list):
            return {"l": [self.encode(x, d) for x in v]}
        if isinstance(v, deque):
            return {"q": [self.encode(x, d) for x in v], "n": v.maxlen}
        if isinstance(v, dict):
            return {"d": [[self.encode(k, d), self.encode(x, d)] for k, x in v.items()]}
        name = _name(type(v))
        if name not in self.classes:
            raise TypeError(f"checkpoint: class {name} is not allowed")
        return {"o": name, "s": {k: self.encode(x, d) for k, x in vars(v).items()}}

    # -- decoding ----------------------------------------------------------------------------------
    def loads(self, data: bytes) -> Any:
        try:
            doc = json.loads(data)
        except (ValueError, UnicodeDecodeError) as exc:
            raise CheckpointError(f"not a checkpoint: {exc}") from None
        return self.decode(doc)

    def decode(self, v: Any, depth: int = 0) -> Any:
        if depth > MAX_DEPTH:
            raise CheckpointError("nested too deeply")
        d = depth + 1
        if v is None or isinstance(v, (bool, int, float, str)):
            return v
        if isinstance(v, list):
            raise CheckpointError("a bare list where a tagged value belongs")
        if not isinstance(v, dict) or len(v) == 0:
            raise CheckpointError(f"unexpected value of type {type(v).__name__}")
        if "f" in v and len(v) == 1:
            if v["f"] not in ("nan", "inf", "-inf"):
                raise CheckpointError(f"bad float {v['f']!r}")
            return float(v["f"])
        if "t" in v and len(v) == 1:
            return tuple(self.decode(x, d) for x in self._seq(v["t"]))
        if "l" in v and len(v) == 1:
            return [self.decode(x, d) for x in self._seq(v["l"])]
        if set(v) == {"q", "n"}:
            n = v["n"]
            if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 0):
                raise CheckpointError(f"bad deque length {n!r}")
            return deque((self.decode(x, d) for x in self._seq(v["q"])), maxlen=n)
        if "d" in v and len(v) == 1:
            out = {}
            for item in self._seq(v["d"]):
                if not isinstance(item, list) or len(item) != 2:
                    raise CheckpointError("a dict entry must be a [key, value] pair")
                key = self.decode(item[0], d)
                try:
                    out[key] = self.decode(item[1], d)
                except TypeError:
                    raise CheckpointError(f"unhashable dict key {key!r}") from None
            return out
        if set(v) == {"a", "s", "b"}:
            return self._array(v)
        if set(v) == {"e", "v"}:
            cls = self._cls(v["e"])
            if not issubclass(cls, Enum):
                raise CheckpointError(f"{v['e']} is not an enum")
            try:
                return cls(self.decode(v["v"], d))
            except ValueError as exc:
                raise CheckpointError(str(exc)) from None
        if set(v) == {"o", "s"}:
            cls = self._cls(v["o"])
            if issubclass(cls, Enum) or not isinstance(v["s"], dict):
                raise CheckpointError(f"bad object record of {v['o']}")
            obj = object.__new__(cls)
            obj.__dict__.update({str(k): self.decode(x, d) for k, x in v["s"].items()})
            return obj
        raise CheckpointError(f"unknown record with keys {sorted(v)[:5]}")

    @staticmethod
    def _seq(v: Any) -> list:
        if not isinstance(v, list):
            raise CheckpointError(f"expected a list, got {type(v).__name__}")
        return v

    def _cls(self, name: Any) -> type:
        if not isinstance(name, str) or name not in self.classes:
            raise CheckpointError(f"type {str(name)[:80]!r} is not allowed in a checkpoint")
        return self.classes[name]

    @staticmethod
    def _array(v: dict) -> np.ndarray:
        try:
            dt = np.dtype(v["a"]) if isinstance(v["a"], str) and len(v["a"]) <= 4 else None
        except TypeError:
            dt = None
        if dt is None or dt.char not in _DTYPES:
            raise CheckpointError(f"array dtype {str(v['a'])[:20]!r} is not allowed")
        shape = v["s"]
        if not isinstance(shape, list) or len(shape) > 8 or not all(
                isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in shape):
            raise CheckpointError(f"bad array shape {str(shape)[:40]}")
        try:
            raw = base64.b64decode(v["b"], validate=True)
        except (TypeError, ValueError):
            raise CheckpointError("bad array data") from None
        if len(raw) != math.prod(shape) * dt.itemsize:
            raise CheckpointError(f"array data of {len(raw)} bytes does not fit shape {shape} of {dt}")
        return np.frombuffer(raw, dtype=dt).reshape(shape).copy()
