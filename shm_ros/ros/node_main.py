"""How every node process starts and stops: init, spin, and one clean stop on SIGINT or SIGTERM
(exit code 0 when every file was closed)."""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
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


#: set by a supervisor in its children's environment: the node dies with that process
SUPERVISOR_PID_ENV = "SHM_SUPERVISOR_PID"
#: where a node writes why it could not start (a bad configuration), for its supervisor to report;
#: the same name with ``.up`` once it runs (set up, spinning: a restarted node takes up its inputs)
REASON_FILE_ENV = "SHM_EXIT_REASON_FILE"
PR_SET_PDEATHSIG = 1  # linux/prctl.h


def die_with_parent() -> None:
    """When started by a supervisor (``SHM_SUPERVISOR_PID``), ask the kernel for SIGTERM when it
    dies (``prctl(PR_SET_PDEATHSIG)``), so a supervisor killed with SIGKILL leaves no node running;
    a supervisor already gone before this call ends the node at once."""
    parent = os.environ.get(SUPERVISOR_PID_ENV)
    if not parent or not sys.platform.startswith("linux"):
        return
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) != 0:
        raise OSError(ctypes.get_errno(), "prctl(PR_SET_PDEATHSIG) failed")
    if os.getppid() != int(parent):  # the supervisor died before the request took effect
        os._exit(143)


class StopSignals:
    """The one shutdown path of a node process: the first SIGINT or SIGTERM (one sent to this
    process, or a terminal's Ctrl-C to the whole process group, which a supervisor then forwards)
    asks the spin loop to end; later ones while the node closes its files are noted and ignored, so
    nothing interrupts a write or a close. No KeyboardInterrupt is raised."""

    def __init__(self, restore: bool = True) -> None:
        self.signum = 0
        self.repeated = 0
        self.restore = restore

    def __enter__(self) -> StopSignals:
        # A process started in the background by a non-interactive shell inherits SIGINT as
        # ignored; a node must still stop on it (and on SIGTERM), so install the handlers explicitly.
        self._previous = {s: signal.signal(s, self._on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        # A supervisor starts its nodes with SIGINT blocked (:func:`held_while_starting`): a Ctrl-C
        # that came while this process imported is delivered now, to the handler.
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        return self

    def __exit__(self, *exc: object) -> None:
        # A node process ignores them from here to its end (``restore=False``): it has stopped and
        # closed its files, so a later signal (the supervisor's SIGINT after the group's SIGTERM)
        # has nothing left to stop. It must neither raise KeyboardInterrupt inside a callback of
        # rclpy's C++ executor threads (that aborts the process: "terminate called ...
        # error_already_set") nor kill the process as the interpreter winds down (it puts the
        # default action back for a handler of its own, not for an ignored signal): exit code 0.
        for s, handler in self._previous.items():
            signal.signal(s, handler if self.restore else signal.SIG_IGN)

    def _on_signal(self, signum: int, frame: Any) -> None:
        if self.signum:
            self.repeated += 1
        else:
            self.signum = signum

    @property
    def stopping(self) -> bool:
        return bool(self.signum)


@contextmanager
def held_while_starting() -> Iterator[None]:
    """Processes started in this block begin with SIGINT blocked (the mask is inherited): a Ctrl-C
    to the process group while a node still imports waits until :class:`StopSignals` is in place,
    and the node then stops cleanly instead of dying of a KeyboardInterrupt inside an import. (A
    SIGTERM there ends it at once, quietly: the default action; a SIGINT to this process meanwhile
    is delivered at the end of the block.)"""
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def delivered(publisher: Any, timeout_s: float = 10.0) -> Callable[[], object]:
    """``before`` of a test hook's :func:`~shm_ros.io.faults.fault_point` after a publication:
    until every subscriber of the reliable ``publisher`` acknowledged what it sent (at most
    ``timeout_s``), so that a node killed there has published its result and its restart
    publishes it again."""
    from rclpy.duration import Duration

    return lambda: publisher.wait_for_all_acked(Duration(seconds=timeout_s))


def report_stop_reason(text: str) -> None:
    """Say why the node cannot start or go on (a bad configuration, a full disk): on stderr and,
    under a supervisor, in its reason file."""
    print(text, file=sys.stderr, flush=True)
    path = os.environ.get(REASON_FILE_ENV)
    if path:
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(text)


def report_up() -> None:
    """Under a supervisor, say that the node is set up and spinning (its ``.up`` file)."""
    path = os.environ.get(REASON_FILE_ENV)
    if path:
        Path(path + ".up").touch()


def spin(factory: Callable[[], Any], args: list[str] | None = None,
         executor_factory: Callable[[], Any] | None = None) -> int:
    """Run one node until shutdown. Callbacks run in a single-threaded executor (the
    multi-threaded one is far slower for data topics), or the one ``executor_factory`` makes; it
    is always spun with a timeout (rclpy's EventsExecutor never runs a callback without one).

    Exit code: 0 after a stop by SIGINT/SIGTERM with every file closed; 2 when the configuration is
    bad (the reason on stderr; a supervisor does not restart it); the error's code when closing
    failed with a :class:`ShmError` (a full disk); any other exception shows its traceback (1)."""
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    die_with_parent()
    node = None
    code = 0
    with StopSignals(restore=False) as stop:
        rclpy.init(args=sys.argv if args is None else args,
                   signal_handler_options=SignalHandlerOptions.NO)
        try:
            if stop.stopping:  # stopped while it started: it holds nothing yet
                return 0
            node = factory()
            if getattr(node, "autostart", False) and not getattr(node, "configured", True):
                # a managed node that could not configure itself: say why and stop (a supervisor
                # stops the graph with this reason rather than restarting it in a loop)
                report_stop_reason(node.config_error)
                return 2
            executor = (executor_factory or SingleThreadedExecutor)()
            executor.add_node(node)
            report_up()
            # Wake up regularly: a signal is only handled once control is back in Python.
            while rclpy.ok() and not stop.stopping:
                executor.spin_once(timeout_sec=0.2)
        except ExternalShutdownException:
            pass
        except ShmError as exc:  # configuration errors, a full disk: the message says what is wrong
            report_stop_reason(str(exc))
            code = exc.exit_code
        finally:
            if node is not None:
                code = close_node(node, code)
            rclpy.try_shutdown()
    return code


def close_node(node: Any, code: int) -> int:
    """Finish the node: its ``close()`` (last outputs), then its files (``destroy_node`` tears
    down stores and bags); a :class:`ShmError` there (a full disk) is one line and its exit code."""
    from shm_ros.io.faults import fault_point

    try:
        fault_point(node.get_name(), "close")
        close = getattr(node, "close", None)
        if close is not None and rclpy.ok() and getattr(node, "configured", True):
            close()
    except ShmError as exc:
        print(exc, file=sys.stderr)
        code = code or exc.exit_code
    finally:
        try:
            node.destroy_node()
        except ShmError as exc:
            print(exc, file=sys.stderr)
            code = code or exc.exit_code
    return code
