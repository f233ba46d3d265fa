"""Start the node graph from a YAML config: one process per node (restarted if it crashes), or all
nodes in one process. There is no ``ros2 launch`` here, so this plays its part.

Config::

    graph: {mode: processes, restart: true, max_restarts: 5}
    nodes:
      ingest:   {parameters: {structure: bridge.yaml, window_s: 600.0}}
      identify: {parameters: {method: ssi-cov}}

Each node runs as ``python -m shm_ros.ros.<kind>_node --ros-args --params-file FILE``; ``kind``
defaults to the key (``kind:`` overrides it, so two identify nodes can run side by side).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from shm_ros.errors import InputError

NODE_KINDS = ("ingest", "identify", "track", "update", "predict", "explain", "recorder")


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


class ConfigError(InputError):
    """The graph config is invalid; the message names the file and the field."""


@dataclass
class NodeSpec:
    name: str
    kind: str
    parameters: dict[str, Any] = field(default_factory=dict)


@dataclass
class GraphConfig:
    nodes: list[NodeSpec]
    mode: str = "processes"
    restart: bool = True
    max_restarts: int = 5
    source: str = "<dict>"
    # the ROS 2 parameters file the graph came from: every node process reads it itself
    params_file: str | None = None


def node_kind(name: str, source: str) -> str:
    """The node kind a node name starts with: ``identify`` and ``identify_data`` are identify nodes."""
    for kind in sorted(NODE_KINDS, key=len, reverse=True):
        if name == kind or name.startswith(kind + "_"):
            return kind
    raise ConfigError(f"{source}: {name}: a node's name must start with its kind "
                      f"({', '.join(NODE_KINDS)})")


def load_graph_config(path_or_dict: str | Path | dict, *, mode: str | None = None,
                      restart: bool | None = None) -> GraphConfig:
    """The graph of a ROS 2 parameters file (``<node>: {ros__parameters: {...}}`` per node, what
    ``--ros-args --params-file`` reads), or of the older layout (``graph: {mode, restart}``,
    ``nodes: {<name>: {kind, parameters}}``)."""
    if isinstance(path_or_dict, dict):
        raw, source = path_or_dict, "<dict>"
    else:
        source = str(path_or_dict)
        try:
            raw = yaml.safe_load(Path(path_or_dict).read_text()) or {}
        except (OSError, yaml.YAMLError) as exc:
            raise ConfigError(f"{source}: cannot read graph config: {exc}") from exc
    if not isinstance(raw, dict):
        raise ConfigError(f"{source}: must be a mapping of node names")
    if "nodes" in raw or "graph" in raw:
        config = _legacy(raw, source)
    else:
        nodes = []
        for name, spec in raw.items():
            if name == "/**":
                raise ConfigError(f"{source}: '/**' (parameters for every node) is not supported: "
                                  "give each node its own section")
            if not isinstance(spec, dict) or set(spec) != {"ros__parameters"}:
                raise ConfigError(f"{source}: {name}: expected `ros__parameters:` (a ROS 2 parameters file)")
            params = spec["ros__parameters"] or {}
            if not isinstance(params, dict):
                raise ConfigError(f"{source}: {name}.ros__parameters must be a mapping")
            nodes.append(NodeSpec(str(name), node_kind(str(name), source), params))
        if not nodes:
            raise ConfigError(f"{source}: no nodes")
        config = GraphConfig(nodes, source=source)
        config.params_file = None if isinstance(path_or_dict, dict) else str(Path(path_or_dict).resolve())
    if mode is not None:
        config.mode = mode
    if restart is not None:
        config.restart = restart
    if config.mode not in ("processes", "single"):
        raise ConfigError(f"{source}: graph mode must be 'processes' or 'single', not {config.mode!r}")
    return config


def _legacy(raw: dict, source: str) -> GraphConfig:
    graph = raw.get("graph", {}) or {}
    nodes = []
    for name, spec in (raw.get("nodes") or {}).items():
        spec = spec or {}
        kind = spec.get("kind", name)
        if kind not in NODE_KINDS:
            raise ConfigError(f"{source}: nodes.{name}.kind: unknown node kind {kind!r} "
                              f"(known: {', '.join(NODE_KINDS)})")
        params = spec.get("parameters", {}) or {}
        if not isinstance(params, dict):
            raise ConfigError(f"{source}: nodes.{name}.parameters must be a mapping")
        nodes.append(NodeSpec(name, kind, params))
    if not nodes:
        raise ConfigError(f"{source}: no nodes")
    return GraphConfig(nodes, graph.get("mode", "processes"), bool(graph.get("restart", True)),
                       int(graph.get("max_restarts", 5)), source)


class Supervisor:
    """Runs each node as a child process; restarts a crashed one; SIGINT stops all cleanly."""

    def __init__(self, config: GraphConfig, log=print) -> None:
        self.config = config
        self.log = log
        self.procs: dict[str, subprocess.Popen] = {}
        self.restarts: dict[str, int] = {n.name: 0 for n in config.nodes}
        self._stopping = False
        self._tmp = tempfile.TemporaryDirectory(prefix="shm-ros-graph-")

    def _params_file(self, node: NodeSpec) -> Path:
        path = Path(self._tmp.name) / f"{node.name}.yaml"
        path.write_text(yaml.safe_dump({node.name: {"ros__parameters": node.parameters}}))
        return path

    def command(self, node: NodeSpec) -> list[str]:
        params = self.config.params_file or str(self._params_file(node))
        return [sys.executable, "-m", f"shm_ros.ros.{node.kind}_node", "--ros-args",
                "-r", f"__node:={node.name}", "--params-file", params]

    def start(self, node: NodeSpec) -> None:
        self.procs[node.name] = subprocess.Popen(self.command(node), env=dict(os.environ))
        self.log(f"[supervisor] started {node.name} (pid {self.procs[node.name].pid})")

    def start_all(self) -> None:
        for node in self.config.nodes:
            self.start(node)

    def poll(self) -> None:
        """Restart nodes that died while the graph is not being stopped."""
        for node in self.config.nodes:
            proc = self.procs.get(node.name)
            if proc is None or proc.poll() is None or self._stopping:
                continue
            code = proc.returncode
            if self.config.restart and self.restarts[node.name] < self.config.max_restarts:
                self.restarts[node.name] += 1
                self.log(f"[supervisor] {node.name} exited with {code}; restarting "
                         f"({self.restarts[node.name]}/{self.config.max_restarts})")
                self.start(node)
            else:
                self.log(f"[supervisor] {node.name} exited with {code}; not restarting")
                self.procs.pop(node.name)

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


def run_single_process(config: GraphConfig) -> int:
    """All nodes in one process and one executor (small deployments)."""
    import importlib

    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    rclpy.init()
    executor = SingleThreadedExecutor()
    nodes = []
    try:
        for spec in config.nodes:
            module = importlib.import_module(f"shm_ros.ros.{spec.kind}_node")
            node = module.make_node(spec.name, spec.parameters)
            nodes.append(node)
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
