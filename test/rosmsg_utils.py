"""Fill ROS 2 messages with random values and compare them field by field (rclpy and rosbags)."""

from __future__ import annotations

import importlib
from typing import Any

import numpy as np

PRIMITIVE_RANGES = {
    "int8": (-128, 127), "uint8": (0, 255), "int16": (-2**15, 2**15 - 1), "uint16": (0, 2**16 - 1),
    "int32": (-2**31, 2**31 - 1), "uint32": (0, 2**32 - 1), "int64": (-2**62, 2**62),
    "uint64": (0, 2**63), "byte": (0, 255), "octet": (0, 255), "char": (0, 127),
}


def rclpy_class(type_name: str) -> type:
    """'shm_interfaces/Mode' or 'shm_interfaces/msg/Mode' -> the rclpy message class."""
    parts = type_name.split("/")
    pkg, name = parts[0], parts[-1]
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def _random_value(type_str: str, rng: np.random.Generator, size: int) -> Any:
    if type_str.startswith("sequence<"):
        inner = type_str[len("sequence<"):-1]
        if inner in ("double", "float"):
            return rng.standard_normal(size).astype(np.float64 if inner == "double" else np.float32)
        if inner in PRIMITIVE_RANGES:
            lo, hi = PRIMITIVE_RANGES[inner]
            dtype = {"int8": np.int8, "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16,
                     "int32": np.int32, "uint32": np.uint32, "int64": np.int64,
                     "uint64": np.uint64}.get(inner, np.uint8)
            return rng.integers(lo, hi, size=size, dtype=np.int64).astype(dtype)
        if inner == "boolean":
            return [bool(b) for b in rng.integers(0, 2, size=size)]
        if inner == "string":
            return [f"s{rng.integers(0, 10**6)}_{i}" for i in range(min(size, 7))]
        return [random_message(rclpy_class(inner), rng, size=min(size, 4)) for _ in range(3)]
    if type_str in ("double", "float"):
        return float(np.float32(rng.standard_normal())) if type_str == "float" else float(rng.standard_normal())
    if type_str in PRIMITIVE_RANGES:
        lo, hi = PRIMITIVE_RANGES[type_str]
        return int(rng.integers(lo, hi))
    if type_str == "boolean":
        return bool(rng.integers(0, 2))
    if type_str == "string":
        return f"text-{rng.integers(0, 10**9)}"
    return random_message(rclpy_class(type_str), rng, size)


def random_message(cls: type, rng: np.random.Generator, size: int = 16) -> Any:
    """An rclpy message of ``cls`` with every field set to a random value (arrays of ``size``)."""
    msg = cls()
    for name, type_str in cls.get_fields_and_field_types().items():
        if name == "stamp" or type_str == "builtin_interfaces/Time":
            value = rclpy_class("builtin_interfaces/Time")(
                sec=int(rng.integers(0, 2**31 - 1)), nanosec=int(rng.integers(0, 10**9)))
        else:
            value = _random_value(type_str, rng, size)
        setattr(msg, name, value)
    return msg


def to_plain(msg: Any) -> Any:
    """Nested plain Python of an rclpy OR rosbags message (same field names in both)."""
    if hasattr(msg, "get_fields_and_field_types"):
        names = list(msg.get_fields_and_field_types())
    elif hasattr(msg, "__dataclass_fields__"):
        names = [n for n in msg.__dataclass_fields__ if n != "__msgtype__" and not n.isupper()]
    else:
        if isinstance(msg, np.ndarray):
            return msg.tolist()
        if isinstance(msg, (list, tuple)) or type(msg).__name__ == "array":
            return [to_plain(v) for v in msg]
        if isinstance(msg, (np.floating, np.integer, np.bool_)):
            return msg.item()
        return msg
    return {n: to_plain(getattr(msg, n)) for n in names}
