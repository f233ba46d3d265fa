"""Node parameters generated from configuration dataclasses (``shm_ros.core.config``).

``config = load_config(node, IdentifyConfig)`` declares one parameter per option of the dataclass
and returns the dataclass built from the values the node was started with, so a node has no
default of its own: the dataclass is the one place that says what an option is.

* **Names**: the field name; the options of a nested configuration (``IdentifyConfig.preprocess``)
  carry its field name as prefix, ``preprocess.lowpass_hz`` (a parameters file may nest them:
  ``preprocess: {lowpass_hz: 20.0}``).
* **Types** follow the option's value type: bool, integer, double, string, string array. They are
  static: ``-p freq_tol:=1`` (an integer for a double) stops the node; write ``1.0``.
* **Unset**: an option whose default is None (``lowpass_hz``: no low-pass) is declared dynamically
  typed and *not set*; ``ros2 param get`` says "Parameter not set" and the dataclass gets None. A
  value given to it must have the option's type (an integer is taken for a double) and is checked
  here. This keeps None out of the value range: no 0 / "" / NaN stands for "none".
* **Descriptors**: the description is the option's help with its default; the choices, if any, are
  the additional constraints ("one of ssi-cov|ssi-data|ssi-io"). Parameters are read once, when the
  node starts, so they are read-only: changing one means restarting the node.
* **Errors** (a value outside the choices, a wrong type, a value the dataclass's own checks refuse)
  raise :class:`ParameterError` (a :class:`~shm_ros.errors.ShmError`) naming the node, the parameter
  and what is allowed; it fails the node's ``configure`` transition (:mod:`shm_ros.ros.managed`).
* A parameter already declared (a node configured again after ``cleanup``) is read, not declared twice.
"""

from __future__ import annotations

from typing import Any, TypeVar

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.parameter import Parameter

from shm_ros.core.config import OptionSpec, format_value, nested_configs, option_specs
from shm_ros.errors import InputError

__all__ = ["declare_config", "config_from_node", "load_config", "check_window_files", "ROS_TYPES", "ParameterError"]


class ParameterError(InputError):
    """A node parameter cannot be used; the message names the node, the parameter and what is allowed."""

T = TypeVar("T")

ROS_TYPES = {bool: Parameter.Type.BOOL, int: Parameter.Type.INTEGER, float: Parameter.Type.DOUBLE,
             str: Parameter.Type.STRING, list: Parameter.Type.STRING_ARRAY}
_TYPE_NAMES = {bool: "bool", int: "integer", float: "double", str: "string", list: "string array"}


def _ros_specs(cls: type, prefix: str) -> list[tuple[str, OptionSpec]]:
    out = [(prefix + s.name, s) for s in option_specs(cls) if s.ros]
    for field, sub in nested_configs(cls):
        out += _ros_specs(sub, f"{prefix}{field}.")
    return out


def _unset(spec: OptionSpec) -> bool:
    """Declared without a value: None, and the empty list (rclpy types an empty list as bytes)."""
    return spec.default is None or spec.default == []


def declare_config(node: Node, cls: type, prefix: str = "") -> None:
    """Declare a parameter for every option of ``cls`` (and of its nested configurations)."""
    for name, spec in _ros_specs(cls, prefix):
        if node.has_parameter(name):
            continue
        constraints = f"one of {'|'.join(spec.choices)}" if spec.choices else ""
        if _unset(spec):
            constraints = "; ".join(c for c in (f"{_TYPE_NAMES[spec.value_type]}, or not set",
                                                constraints) if c)
        descriptor = ParameterDescriptor(name=name, description=spec.describe(),
                                         additional_constraints=constraints, read_only=True,
                                         dynamic_typing=_unset(spec))
        try:
            node.declare_parameter(name, None if _unset(spec) else spec.default, descriptor)
        except (ParameterException, TypeError, ValueError) as exc:
            raise ParameterError(f"{node.get_name()}: parameter '{name}' must be a "
                             f"{_TYPE_NAMES[spec.value_type]} (default "
                             f"{format_value(spec.default)}): {exc}") from None


def config_from_node(node: Node, cls: type[T], prefix: str = "") -> T:
    """The dataclass ``cls`` from the node's (declared) parameters; options not declared as
    parameters (``ros=False``) keep their defaults."""
    values: dict[str, Any] = {}
    for spec in option_specs(cls):
        if spec.ros:
            name = prefix + spec.name
            values[spec.name] = _checked(node, name, spec, node.get_parameter(name).value)
    for field, sub in nested_configs(cls):
        values[field] = config_from_node(node, sub, f"{prefix}{field}.")
    where = prefix.rstrip(".") or "parameters"
    try:
        config = cls(**values)
        validate = getattr(config, "validate", None)
        if validate is not None:
            validate()
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"{node.get_name()}: {where}: {exc}") from None
    return config


def load_config(node: Node, cls: type[T], prefix: str = "") -> T:
    """Declare the parameters of ``cls`` and read them back: what a node does at start."""
    declare_config(node, cls, prefix)
    return config_from_node(node, cls, prefix)


def _checked(node: Node, name: str, spec: OptionSpec, value: Any) -> Any:
    if value is None:  # not set (only options declared unset can be)
        return None if spec.default is None else list(spec.default)
    kind = spec.value_type
    ok = (isinstance(value, bool) if kind is bool else
          isinstance(value, int) and not isinstance(value, bool) if kind is int else
          isinstance(value, int | float) and not isinstance(value, bool) if kind is float else
          isinstance(value, str) if kind is str else
          isinstance(value, list | tuple) and all(isinstance(v, str) for v in value))
    if not ok:
        raise ParameterError(f"{node.get_name()}: parameter '{name}' must be a {_TYPE_NAMES[kind]}, "
                         f"got {value!r}")
    value = float(value) if kind is float else list(value) if kind is list else value
    if spec.choices and value not in spec.choices:
        raise ParameterError(f"{node.get_name()}: parameter '{name}' must be one of "
                         f"{'|'.join(spec.choices)}, got {value!r}")
    return value


def check_window_files(node: str, parameter: str, paths: list[str] | tuple[str, ...]) -> None:
    """Every path a readable analysis window file, else :class:`ParameterError` naming the node, the
    parameter and the file (a node checks its window-file parameters at its start)."""
    from shm_ros.errors import ShmError
    from shm_ros.io.window_files import load_window

    for path in paths:
        try:
            load_window(path)
        except ShmError as exc:
            raise ParameterError(f"{node}: parameter '{parameter}': {exc}") from None
