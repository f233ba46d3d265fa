"""How every node process starts and stops: init, spin, clean exit 0 on Ctrl-C / SIGINT."""

from __future__ import annotations

import signal
import sys
from collections.abc import Callable
from typing import Any

import rclpy
from rclpy.parameter import Parameter

from shm_ros.errors import ShmError


def overrides(parameters: dict[str, Any] | None, prefix: str = "") -> list[Parameter]:
    """Parameter overrides from a dict (single-process graphs, tests). A nested mapping gives
    dotted names, as in a parameters file (``{"preprocess": {"lowpass_hz": 20.0}}`` is
    ``preprocess.lowpass_hz``); None leaves a parameter at its default, as if it were not given."""
    out: list[Parameter] = []
    for key, value in (parameters or {}).items():
        if isinstance(value, dict):
            out += overrides(value, f"{prefix}{key}.")
        elif value is not None:
            out.append(Parameter(prefix + key, value=value))
    return out


def _terminate(signum, frame) -> None:
    raise KeyboardInterrupt


def spin(factory: Callable[[], Any], args: list[str] | None = None,
         executor_factory: Callable[[], Any] | None = None) -> int:
    """Run one node until shutdown. Callbacks run in a single-threaded executor (the
    multi-threaded one is far slower for data topics), or the one ``executor_factory`` makes; it
    is always spun with a timeout (rclpy's EventsExecutor never runs a callback without one)."""
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    # Ctrl-C arrives as KeyboardInterrupt (not as a context shutdown), so a node can still publish
    # what it holds (e.g. ingest's last window) before the context goes away.
    # A process started in the background by a non-interactive shell inherits SIGINT as ignored;
    # a node must still stop on it (and on SIGTERM), so install the handlers explicitly.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, _terminate)
    rclpy.init(args=sys.argv if args is None else args,
               signal_handler_options=SignalHandlerOptions.NO)
    node = None
    code = 0
    try:
        node = factory()
        if getattr(node, "autostart", False) and not getattr(node, "configured", True):
            # a managed node that could not configure itself: say why and stop (a supervisor or
            # launch respawns it, so a file fixed meanwhile is taken up)
            print(node.config_error, file=sys.stderr)
            return 2
        executor = (executor_factory or SingleThreadedExecutor)()
        executor.add_node(node)
        # Wake up regularly: a signal is only handled once control is back in Python.
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.2)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ShmError as exc:  # configuration errors: the message says what is wrong
        print(exc, file=sys.stderr)
        code = 2
    finally:
        if node is not None:
            close = getattr(node, "close", None)
            try:
                if close is not None and rclpy.ok() and getattr(node, "configured", True):
                    close()
            except KeyboardInterrupt:
                pass
            node.destroy_node()
        rclpy.try_shutdown()
    return code
