"""One definition per user-settable option.

A stage's configuration is a dataclass whose fields are made with :func:`option`: the default, a
one-line help and, for a fixed set of values, the choices (an ``enum.StrEnum``). The ROS parameter
declarations of the stage's node (``shm_ros.ros.params``) and the options of its ``shm-ros``
command (``shm_ros.commands.options``) are generated from these fields, so node, command line and
core cannot disagree on a default.
"""

from __future__ import annotations

import dataclasses
import enum
import types
import typing
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

NO_DEFAULT: Any = dataclasses.MISSING


@dataclass(frozen=True)
class OptionSpec:
    """What the generators need to know of one option."""

    name: str
    default: Any
    help: str
    choices: tuple[str, ...] | None = None
    ros: bool = True  # declared as a node parameter
    cli: bool = True  # offered as a command-line option
    value_type: type = str  # value type: bool, int, float, str or list (of str); None allowed when optional
    optional: bool = False  # None is a value (the field is annotated ``X | None``)

    def describe(self) -> str:
        """The help with the default and the choices, as node and command line show it."""
        text = f"{self.help} (default: {format_value(self.default)}"
        return text + (f"; one of {'|'.join(self.choices)})" if self.choices else ")")


def option(default: Any, help: str, *, choices: type[enum.Enum] | Sequence[str] | None = None,
           ros: bool = True, cli: bool = True) -> Any:
    """A dataclass field with its help and choices; list defaults are copied per instance."""
    meta = {"help": help, "choices": _choice_values(choices), "ros": ros, "cli": cli}
    if isinstance(default, list | dict | set):
        return dataclasses.field(default_factory=lambda: type(default)(default), metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def option_specs(cls: type) -> list[OptionSpec]:
    """The options of a configuration dataclass, in declaration order (plain fields without
    :func:`option` metadata, e.g. nested configurations, are left out)."""
    out: list[OptionSpec] = []
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        if "help" not in f.metadata:
            continue
        if f.default is not dataclasses.MISSING:
            default = f.default
        elif f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        else:
            default = NO_DEFAULT
        value_type, optional = _value_type(hints[f.name], default, f"{cls.__name__}.{f.name}")
        out.append(OptionSpec(f.name, default, f.metadata["help"], f.metadata["choices"],
                              f.metadata["ros"], f.metadata["cli"], value_type, optional))
    return out


def nested_configs(cls: type) -> list[tuple[str, type]]:
    """Fields of ``cls`` that are configurations themselves (e.g. ``IdentifyConfig.preprocess``):
    plain fields whose default is made by a dataclass. Their options are offered with the field
    name as prefix (``preprocess.lowpass_hz``)."""
    out: list[tuple[str, type]] = []
    for f in dataclasses.fields(cls):
        factory = f.default_factory
        if ("help" not in f.metadata and isinstance(factory, type) and dataclasses.is_dataclass(factory)):
            out.append((f.name, factory))
    return out


def format_value(value: Any) -> str:
    """A default as help texts show it: ``unset`` for None, lists comma-separated."""
    if value is None:
        return "unset"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, list | tuple):
        return ",".join(str(v) for v in value) if value else "[]"
    return str(value)


_SCALARS = (bool, int, float, str, list)


def _value_type(annotation: Any, default: Any, where: str) -> tuple[type, bool]:
    """``(value type, optional)`` of an option from its annotation (``int | None`` -> int, True)."""
    optional = False
    if typing.get_origin(annotation) in (types.UnionType, typing.Union):
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        optional = len(args) < len(typing.get_args(annotation))
        if len(args) != 1:
            raise TypeError(f"{where}: an option has one value type, not {annotation}")
        annotation = args[0]
    origin = typing.get_origin(annotation) or annotation
    if origin is list and typing.get_args(annotation) not in ((), (str,)):
        raise TypeError(f"{where}: list options hold strings, not {annotation}")
    if origin not in _SCALARS:
        raise TypeError(f"{where}: option type must be one of bool, int, float, str, list[str], "
                        f"not {annotation}")
    return origin, optional


def check_choice(section: str, name: str, value: Any, choices: type[enum.Enum] | Sequence[str]) -> None:
    """Raise ``ValueError`` naming ``section.name`` when ``value`` is not one of ``choices``."""
    allowed = _choice_values(choices) or ()
    if value not in allowed:
        raise ValueError(f"{section}.{name} must be one of {'|'.join(allowed)}, got {value!r}")


def _choice_values(choices: type[enum.Enum] | Sequence[str] | None) -> tuple[str, ...] | None:
    if choices is None:
        return None
    if isinstance(choices, type) and issubclass(choices, enum.Enum):
        return tuple(str(m.value) for m in choices)
    return tuple(str(c) for c in choices)
