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
    for f in dataclasses.fields(cls):
        if "help" not in f.metadata:
            continue
        if f.default is not dataclasses.MISSING:
            default = f.default
        elif f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        else:
            default = NO_DEFAULT
        out.append(OptionSpec(f.name, default, f.metadata["help"], f.metadata["choices"],
                              f.metadata["ros"], f.metadata["cli"]))
    return out


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
