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


class Supervisor:
    """Runs each node of the plan as a child process; respawns one that dies (after the registry's
    delay, at most ``max_restarts`` times); SIGINT stops all cleanly."""

    def __init__(self, config: GraphConfig, log=print, autostart: bool = True) -> None:
        self.config = config
        self.log = log
        self.plan = {n.name: n for n in launch_plan(config, autostart)}
        self.procs: dict[str, subprocess.Popen] = {}
        self.restarts: dict[str, int] = {n.name: 0 for n in config.nodes}
        self._due: dict[str, float] = {}  # node -> when it is respawned
        self._stopping = False
        self._tmp = tempfile.TemporaryDirectory(prefix="shm-ros-graph-")

    def _params_file(self, node: NodeLaunch) -> Path:
        """The node's parameters under its fully qualified name (what ``--params-file`` matches)."""
        path = Path(self._tmp.name) / f"{node.name}.yaml"
        path.write_text(yaml.safe_dump({f"{node.namespace}/{node.name}": {"ros__parameters": node.parameters}}))
        return path

    def command(self, node: NodeSpec | NodeLaunch) -> list[str]:
        launch = self.plan[node.name]
        ns = ["-r", f"__ns:={launch.namespace}"] if launch.namespace else []
        return [sys.executable, "-m", launch.module, "--ros-args", "-r", f"__node:={launch.name}", *ns,
                "--params-file", str(self._params_file(launch))]

    def start(self, node: NodeSpec | NodeLaunch) -> None:
        self.procs[node.name] = subprocess.Popen(self.command(node), env=dict(os.environ))
        self.log(f"[supervisor] started {node.name} (pid {self.procs[node.name].pid})")

    def start_all(self) -> None:
        if self.config.mode == "single":
            self.procs["graph"] = subprocess.Popen(self.single_command(), env=dict(os.environ))
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

    def poll(self) -> None:
        """Respawn nodes that died while the graph is not being stopped."""
        now = time.monotonic()
        for name, node in self.plan.items():
            if self._stopping:
                return
            if name in self._due:
                if now >= self._due[name]:
                    del self._due[name]
                    self.start(node)
                continue
            proc = self.procs.get(name)
            if proc is None or proc.poll() is None:
                continue
            code = proc.returncode
            if node.respawn and self.restarts[name] < self.config.max_restarts:
                self.restarts[name] += 1
                self.log(f"[supervisor] {name} exited with {code}; restarting in {node.respawn_delay_s:g} s "
                         f"({self.restarts[name]}/{self.config.max_restarts})")
                self._due[name] = now + node.respawn_delay_s
            else:
                self.log(f"[supervisor] {name} exited with {code}; not restarting")
                self.procs.pop(name)

    def stop_all(self, timeout: float = 10.0) -> int:
        """SIGINT every child, wait, escalate; 0 when all stopped cleanly."""
        self._stopping = True
        for proc in self.procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        worst = 0
        end = time.monotonic() + timeout
        for name, proc in self.procs.items():
            try:
                code = proc.wait(timeout=max(end - time.monotonic(), 0.1))
            except subprocess.TimeoutExpired:
                proc.terminate()
                try:
                    code = proc.wait(timeout=3)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    code = proc.wait()
                self.log(f"[supervisor] {name} did not stop on SIGINT")
                worst = 1
            if code not in (0, -signal.SIGINT, 130):
                self.log(f"[supervisor] {name} stopped with exit code {code}")
                worst = 1
        self._tmp.cleanup()
        return worst

    def run(self) -> int:
        """Start, watch, and stop on SIGINT/SIGTERM; returns the exit code."""
        stop = {"flag": False}

        def _on_signal(signum, frame):
            stop["flag"] = True

        previous = {s: signal.signal(s, _on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            self.start_all()
            while not stop["flag"]:
                self.poll()
                time.sleep(0.2)
        finally:
            code = self.stop_all()
            for s, h in previous.items():
                signal.signal(s, h)
        self.log("[supervisor] all nodes stopped")
        return code


def run_single_process(config: GraphConfig, autostart: bool = True) -> int:
    """All nodes in one process and one executor (small deployments); a node that cannot configure
    itself stops the graph (exit code 2, the reason on stderr)."""
    import importlib

    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    rclpy.init()
    executor = SingleThreadedExecutor()
    nodes = []
    try:
        for launch in launch_plan(config, autostart):
            node = importlib.import_module(launch.module).make_node(launch.name, launch.parameters, launch.namespace)
            nodes.append(node)
            if autostart and not node.configured:
                print(node.config_error, file=sys.stderr)
                return 2
            executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        for node in nodes:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0
