"""Command-line options generated from configuration dataclasses (``shm_ros.core.config``).

``add_options(parser, IdentifyConfig)`` adds one option per field: ``max_order`` becomes
``--max-order``, with the field's type, its choices and its help followed by the default; a bool
becomes ``--uncertainty`` / ``--no-uncertainty``; a list of strings is given comma-separated
(``--reference-channels f3,f8``); a number must be finite (``nan`` and ``inf`` are refused). The
options of a nested configuration carry its field name:
``IdentifyConfig.preprocess.lowpass_hz`` is ``--preprocess.lowpass-hz`` (the same name as the
node parameter ``preprocess.lowpass_hz``).

``config_from_args(IdentifyConfig, args)`` builds the dataclass back: only the options the user gave
override the defaults (or ``base``, e.g. a configuration file), so a default lives only in the
dataclass. The parser's defaults are the dataclass's, for ``--help`` and for readers of ``args``.
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any, TypeVar

from shm_ros.commands.checks import finite_float
from shm_ros.core.config import OptionSpec, nested_configs, option_specs

__all__ = ["add_options", "config_from_args", "flag", "given"]

T = TypeVar("T")
_GIVEN = "_options_given"  # namespace attribute: the dests the user set


def flag(dest: str) -> str:
    """``preprocess.lowpass_hz`` -> ``--preprocess.lowpass-hz``."""
    return "--" + dest.replace("_", "-")


def given(args: argparse.Namespace) -> set[str]:
    """The generated options the user gave on the command line (by dest)."""
    return set(getattr(args, _GIVEN, ()))


def _mark(namespace: argparse.Namespace, dest: str) -> None:
    setattr(namespace, _GIVEN, given(namespace) | {dest})


class _Store(argparse.Action):
    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        setattr(namespace, self.dest, values)
        _mark(namespace, self.dest)


class _Switch(argparse.BooleanOptionalAction):
    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        super().__call__(parser, namespace, values, option_string)
        _mark(namespace, self.dest)


def _comma_list(text: str) -> list[str]:
    return [s.strip() for s in text.split(",") if s.strip()]


def _cli_specs(cls: type, prefix: str) -> list[tuple[str, OptionSpec]]:
    out = [(prefix + s.name, s) for s in option_specs(cls) if s.cli]
    for field, sub in nested_configs(cls):
        out += _cli_specs(sub, f"{prefix}{field}.")
    return out


def add_options(parser: argparse.ArgumentParser | argparse._ArgumentGroup, cls: type,
                prefix: str = "", *, aliases: Mapping[str, Sequence[str]] | None = None) -> None:
    """Add an option for every field of ``cls`` (and of its nested configurations) offered on the
    command line. ``aliases`` maps a dest to further option strings (older spellings)."""
    aliases = aliases or {}
    for dest, spec in _cli_specs(cls, prefix):
        names = [flag(dest), *aliases.get(dest, ())]
        text = spec.describe().replace("%", "%%")  # argparse formats help with %
        if spec.value_type is bool:
            parser.add_argument(*names, dest=dest, action=_Switch, default=spec.default, help=text)
            continue
        kind: Any = {list: _comma_list, float: finite_float}.get(spec.value_type, spec.value_type)
        metavar = "A,B,..." if spec.value_type is list else None if spec.choices else spec.name.upper()
        parser.add_argument(*names, dest=dest, action=_Store, type=kind, default=spec.default,
                            choices=list(spec.choices) if spec.choices else None, metavar=metavar,
                            help=text)


def config_from_args(cls: type[T], args: argparse.Namespace, prefix: str = "",
                     base: T | None = None) -> T:
    """``base`` (default: ``cls()``) with the options the user gave; the dataclass's own checks
    (``__post_init__``) run, ``validate()`` is left to the caller."""
    config: Any = base if base is not None else cls()
    user = given(args)
    changes: dict[str, Any] = {}
    for spec in option_specs(cls):
        dest = prefix + spec.name
        if spec.cli and dest in user:
            changes[spec.name] = getattr(args, dest)
    for field, sub in nested_configs(cls):
        changes[field] = config_from_args(sub, args, f"{prefix}{field}.", getattr(config, field))
    return dataclasses.replace(config, **changes)
