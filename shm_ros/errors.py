"""The project's errors: one base class for everything a user can act on.

Every error that bad input, a bad option or a named numerical failure can raise derives from
:class:`ShmError`; its message names the file, topic, option or field and what is wrong. The command
line catches :class:`ShmError` alone and prints it as one line with the class's ``exit_code``; any
other exception is a bug and shows its traceback (exit code 1). Nodes report :class:`ShmError` on
``/diagnostics`` and go on. This module imports nothing from the package, so every layer may use it.
"""

from __future__ import annotations


class ShmError(Exception):
    """An error the user can act on; the message says what and where."""

    exit_code = 2


class InputError(ShmError, ValueError):
    """Bad input: a file, topic, option or field that cannot be used as given."""


class NumericalFailure(ShmError, ArithmeticError):
    """A named numerical failure inside a fit (no convergence, a singular or non-finite matrix).

    Inside explain a candidate whose fit raises it is marked failed with this reason and the verdict
    is still written; elsewhere it stops the command with its message."""


class NoWindowsError(ShmError):
    """The input holds no analysis window at all: nothing to do (exit code 3)."""

    exit_code = 3
