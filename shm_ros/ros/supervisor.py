"""Start the node graph of a ROS 2 parameters file (:mod:`shm_ros.ros.graph_config`): one process
per node, respawned when it dies, or all nodes in one process. It starts what
``launch/pipeline.launch.py`` starts (:func:`~shm_ros.ros.graph_config.launch_plan`), for machines
without ``ros2 launch``.

Each node runs as ``python -m shm_ros.ros.<kind>_node --ros-args -r __node:=NAME [-r __ns:=NS]
--params-file FILE``, FILE holding its parameters (``autostart: true`` among them: a managed node
configures and activates itself; with ``autostart: false`` a lifecycle manager does it through the
standard ``lifecycle_msgs`` services).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

from shm_ros.ros.graph_config import (  # noqa: F401 (re-exported: the graph's names live here too)
    ConfigError,
    GraphConfig,
    NodeLaunch,
    NodeSpec,
    launch_plan,
    load_graph_config,
    node_kind,
)
from shm_ros.ros.registry import KINDS as NODE_KINDS  # noqa: F401


def node_process(kind: str, params: dict[str, Any], name: str | None = None,
                 capture: bool = True) -> subprocess.Popen:
    """Start one node as its own process with ``-p key:=value`` parameters."""
    args = [sys.executable, "-m", f"shm_ros.ros.{kind}_node", "--ros-args"]
    if name:
        args += ["-r", f"__node:={name}"]
    for key, value in params.items():
        if isinstance(value, list):
            value = "[" + ",".join(str(v) for v in value) + "]"
        args += ["-p", f"{key}:={value}"]
    out = subprocess.PIPE if capture else None
    return subprocess.Popen(args, stdout=out, stderr=subprocess.STDOUT if capture else None, text=True)


def stop_process(proc: subprocess.Popen, timeout: float = 20.0) -> tuple[int, str]:
    """SIGINT, wait, kill if needed; returns (exit code, captured output); -9 when killed."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        try:
            out, _ = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:  # a process the node started still holds its output pipe
            out = ""
            proc.wait()
            if proc.stdout is not None:
                proc.stdout.close()
        return -9, out or ""
    return proc.returncode, out or ""


#: respawn delays double after each restart of a node up to this, s
MAX_RESPAWN_DELAY_S = 60.0
#: a node that ran this long before it died starts its back-off afresh, s
STABLE_AFTER_S = 60.0
#: a node that takes longer than this to stop is named in the log, s
SLOW_STOP_S = 5.0


class Supervisor:
    """Runs each node of the plan as a child process; respawns one that dies (after the registry's
    delay, doubled after each restart up to ``MAX_RESPAWN_DELAY_S``, at most ``max_restarts``
    times); SIGINT or SIGTERM stops all cleanly.

    A node that exits with code 2 has a bad configuration (or a full disk): it is not restarted, the
    graph is stopped and the node's reason is logged (exit code 2). The exit code is 1 when something
    may have been lost: a node died whose restart cannot take up what it held (the registry's
    ``recovers``: ingest's samples of the window it was filling), or one that was not running again
    (set up and spinning) at the stop, or was not restarted; or a node did not stop cleanly. A node
    that died and came back, of a kind that takes up what it held from its inputs' history
    (identify, track, update, predict, explain, recorder: transient-local topics, the track store),
    lost nothing: the exit code stays 0 and the log names it. The children die with the supervisor
    (``SHM_SUPERVISOR_PID``: each asks the kernel for a parent-death signal), so killing it with
    SIGKILL leaves no node running."""

    def __init__(self, config: GraphConfig, log=print, autostart: bool = True) -> None:
        self.config = config
        self.log = log
        self.plan = {n.name: n for n in launch_plan(config, autostart)}
        self.procs: dict[str, subprocess.Popen] = {}
        self.restarts: dict[str, int] = {n.name: 0 for n in config.nodes}
        self._due: dict[str, float] = {}  # node -> when it is respawned
        self._started: dict[str, float] = {}  # node -> when its current process started
        self._stopping = False
        self._signals: Any = None  # the StopSignals of :meth:`run`: a stop asked for, not yet begun
        self.died: dict[str, list[int]] = {}  # node -> the exit codes of its deaths while the graph ran
        self.lost: dict[str, str] = {}  # node -> why what it held may be lost (set by stop_all)
        self.fatal = ""  # why the graph stopped by itself (a bad configuration, a node given up)
        self.fatal_code = 0
        self._tmp = tempfile.TemporaryDirectory(prefix="shm-ros-graph-")

    def _params_file(self, node: NodeLaunch) -> Path:
        """The node's parameters under its fully qualified name (what ``--params-file`` matches)."""
        path = Path(self._tmp.name) / f"{node.name}.yaml"
        path.write_text(yaml.safe_dump({f"{node.namespace}/{node.name}": {"ros__parameters": node.parameters}}))
        return path

    def _reason_file(self, name: str) -> Path:
        return Path(self._tmp.name) / f"{name}.reason"

    def _up_file(self, name: str) -> Path:
        """Written by the node once it is set up and spinning (:func:`~shm_ros.ros.node_main.report_up`)."""
        return Path(self._tmp.name) / f"{name}.reason.up"

    def _why_lost(self, name: str) -> str:
        """Why the node ``name``, which died, may have lost what it held ("" when it did not): its
        kind cannot take it up again, or its current process is not running and spinning (not
        restarted, or not yet)."""
        from shm_ros.ros.registry import node_kind as registry_entry

        died = f"{name} exited with {' and '.join(str(c) for c in self.died[name])}"
        if not registry_entry(self.plan[name].kind).recovers:
            return f"{died} (a restart cannot take up what it held)"
        proc = self.procs.get(name)
        if name in self._due:
            return f"{died} (waiting for its restart at the stop)"
        if proc is None:
            return f"{died} (not restarted)"
        if not self._up_file(name).exists():
            return f"{died} (its restart not yet up at the stop)"
        if proc.returncode is not None:
            return f"{died} (not running at the stop)"
        return ""

    def command(self, node: NodeSpec | NodeLaunch) -> list[str]:
        launch = self.plan[node.name]
        ns = ["-r", f"__ns:={launch.namespace}"] if launch.namespace else []
        return [sys.executable, "-m", launch.module, "--ros-args", "-r", f"__node:={launch.name}", *ns,
                "--params-file", str(self._params_file(launch))]

    def _env(self, name: str) -> dict[str, str]:
        from shm_ros.ros.node_main import REASON_FILE_ENV, SUPERVISOR_PID_ENV

        return {**os.environ, SUPERVISOR_PID_ENV: str(os.getpid()), REASON_FILE_ENV: str(self._reason_file(name))}

    def start(self, node: NodeSpec | NodeLaunch) -> None:
        from shm_ros.ros.node_main import held_while_starting

        self._reason_file(node.name).unlink(missing_ok=True)
        self._up_file(node.name).unlink(missing_ok=True)
        with held_while_starting():  # a Ctrl-C while it imports stops it cleanly once it can
            self.procs[node.name] = subprocess.Popen(self.command(node), env=self._env(node.name))
        self._started[node.name] = time.monotonic()
        self.log(f"[supervisor] started {node.name} (pid {self.procs[node.name].pid})")

    def start_all(self) -> None:
        from shm_ros.ros.node_main import held_while_starting

        if self.config.mode == "single":
            with held_while_starting():
                self.procs["graph"] = subprocess.Popen(self.single_command(), env=self._env("graph"))
            self.log(f"[supervisor] started the graph in one process (pid {self.procs['graph'].pid})")
            return
        for node in self.plan.values():
            self.start(node)

    def single_command(self) -> list[str]:
        """``shm-ros run --single-process`` of the whole plan: every node in one process."""
        path = Path(self._tmp.name) / "graph.yaml"
        path.write_text(yaml.safe_dump({n.name: {"ros__parameters": n.parameters} for n in self.plan.values()}))
        ns = ["--namespace", self.config.namespace] if self.config.namespace else []
        return [sys.executable, "-m", "shm_ros.cli", "run", str(path), "--single-process", "--no-restart", *ns]

    def respawn_delay(self, node: NodeLaunch, restart: int) -> float:
        """Seconds before the ``restart``-th respawn (1, 2, ...): the node's delay, doubled each time."""
        return min(node.respawn_delay_s * 2.0 ** (restart - 1), max(MAX_RESPAWN_DELAY_S, node.respawn_delay_s))

    def poll(self) -> str:
        """Respawn nodes that died while the graph is not being stopped; returns why the graph
        must stop (a node with a bad configuration, or one not restarted), else ""."""
        now = time.monotonic()
        for name, node in self.plan.items():
            if self._stopping or (self._signals is not None and self._signals.stopping):
                return ""  # a node that ended meanwhile may have ended on the same signal: stop_all sees it
            if name in self._due:
                if now >= self._due[name]:
                    del self._due[name]
                    self.start(node)
                continue
            proc = self.procs.get(name)
            if proc is None or proc.poll() is None:
                continue
            code = proc.returncode
            if code == 2:  # a bad configuration, a full disk: restarting cannot help
                reason_file = self._reason_file(name)
                reason = reason_file.read_text().strip() if reason_file.exists() else ""
                self.procs.pop(name)
                self.fatal_code = 2
                return f"{name} cannot go on: {reason or 'exit code 2 (a bad configuration)'}"
            self.died.setdefault(name, []).append(code)
            if now - self._started.get(name, now) >= STABLE_AFTER_S:
                self.restarts[name] = 0
            if node.respawn and self.restarts[name] < self.config.max_restarts:
                self.restarts[name] += 1
                delay = self.respawn_delay(node, self.restarts[name])
                self.log(f"[supervisor] {name} exited with {code}; restarting in {delay:g} s "
                         f"({self.restarts[name]}/{self.config.max_restarts})")
                self._due[name] = now + delay
            else:
                self.procs.pop(name)
                self.fatal_code = 1
                return f"{name} exited with {code} and is not restarted"
        return ""

    def stop_all(self, timeout: float = 20.0) -> int:
        """SIGINT every child that is up (a second one, as from a terminal's Ctrl-C, does no harm: a
        node ignores it while it closes its files), SIGTERM one still starting (it holds nothing
        yet; a SIGINT would wait in it until its handlers are in place, see
        :func:`~shm_ros.ros.node_main.held_while_starting`, while SIGTERM ends it at once, quietly),
        wait, escalate; 0 when all stopped cleanly and no node that died may have lost what it
        held; ``lost`` names each node that makes it 1, once, with why (``died`` has every death).
        A node dying of SIGINT (-2) did not stop cleanly: a node started here never gets it unhandled."""
        self._stopping = True
        crashed: dict[str, str] = {}  # the one process of a single-process graph, ended before the stop
        for name, proc in self.procs.items():  # ended before this stop saw it
            if name in self._due or proc.poll() is None:
                continue
            if proc.returncode in (0, 130, -signal.SIGTERM):
                # ended by the stop's own signal (a Ctrl-C or SIGTERM to the process group reaches
                # every node as it reaches the supervisor): stopped cleanly, or, still starting
                # (a SIGTERM before its handlers), it held nothing yet (a restart of a node that
                # died is in ``died`` already, and counted below as not back at the stop)
                if not self._up_file(name).exists():
                    self.log(f"[supervisor] {name} was still starting at the stop (exit code {proc.returncode})")
            elif self.config.mode != "single":  # died just before the stop
                self.died.setdefault(name, []).append(proc.returncode)
            else:
                crashed[name] = f"{name} stopped with exit code {proc.returncode}"
        self.lost = {name: why for name in self.died if (why := self._why_lost(name))} | crashed
        waited = {name: proc for name, proc in self.procs.items() if proc.returncode is None}
        starting = {name for name in waited if not self._up_file(name).exists()}
        for name, proc in waited.items():
            proc.send_signal(signal.SIGTERM if name in starting else signal.SIGINT)
        start = time.monotonic()
        end = start + timeout
        for name, proc in waited.items():
            try:
                code = proc.wait(timeout=max(end - time.monotonic(), 0.1))
                if (took := time.monotonic() - start) > SLOW_STOP_S:  # a slow stop, before it is a lost one
                    self.log(f"[supervisor] {name} took {took:.0f} s to stop (exit code {code})")
            except subprocess.TimeoutExpired:
                proc.terminate()
                try:
                    code = proc.wait(timeout=3)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    code = proc.wait()
                self.lost.setdefault(name, f"{name} did not stop on SIGINT (exit code {code})")
                continue
            if name in starting and code in (0, -signal.SIGTERM):
                self.log(f"[supervisor] {name} was still starting at the stop (exit code {code})")
            elif code not in (0, 130):
                self.lost.setdefault(name, f"{name} stopped with exit code {code}")
        self._tmp.cleanup()
        return max(self.fatal_code, 1 if self.lost else 0)

    def run(self) -> int:
        """Start, watch, and stop on SIGINT/SIGTERM (or when the graph cannot go on); returns the
        exit code."""
        from shm_ros.ros.node_main import StopSignals, die_with_parent

        die_with_parent()  # a supervisor run by a supervisor (single-process mode)
        with StopSignals() as stop:
            self._signals = stop
            try:
                self.start_all()
                while not stop.stopping:
                    self.fatal = self.poll()
                    if self.fatal:
                        self.log(f"[supervisor] {self.fatal}: stopping the graph")
                        break
                    time.sleep(0.2)
            finally:
                code = self.stop_all()
        if self.lost:
            self.log(f"[supervisor] what a node held when it died may be lost: {'; '.join(self.lost.values())}")
        if recovered := [name for name in self.died if name not in self.lost]:
            self.log("[supervisor] restarted after a crash, recovered from their inputs: " + ", ".join(recovered))
        self.log(f"[supervisor] all nodes stopped (exit code {code})")
        return code


def run_single_process(config: GraphConfig, autostart: bool = True) -> int:
    """All nodes in one process and one executor (small deployments); a node that cannot configure
    itself stops the graph (exit code 2, the reason on stderr). The same stop as a node process:
    SIGINT or SIGTERM ends the loop and every node is closed."""
    import importlib

    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from shm_ros.ros.node_main import StopSignals, close_node, die_with_parent, report_stop_reason, report_up

    die_with_parent()
    nodes = []
    code = 0
    with StopSignals(restore=False) as stop:
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
        executor = SingleThreadedExecutor()
        try:
            for launch in launch_plan(config, autostart):
                node = importlib.import_module(launch.module).make_node(launch.name, launch.parameters,
                                                                        launch.namespace)
                nodes.append(node)
                if autostart and not node.configured:
                    report_stop_reason(node.config_error)
                    return 2
                executor.add_node(node)
            report_up()
            while rclpy.ok() and not stop.stopping:
                executor.spin_once(timeout_sec=0.2)
        except ExternalShutdownException:
            pass
        finally:
            for node in nodes:
                code = close_node(node, code)
            rclpy.try_shutdown()
    return code
