"""A node graph from a ROS 2 parameters file, and the plan of what to start for it.

The graph file is a standard ROS 2 parameters file (``<node>: {ros__parameters: {...}}``); each key
is a node whose name starts with its kind (``identify_data`` is a second identify node). The older
layout (``graph: {mode, restart}``, ``nodes: {<name>: {kind, parameters}}``) is still read.

:func:`launch_plan` turns a graph into the nodes to start, each with its executable, namespace,
parameters and respawn policy from the node registry (:mod:`shm_ros.ros.registry`). The supervisor
behind ``shm-ros run`` and ``launch/pipeline.launch.py`` both start exactly this plan.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from shm_ros.errors import InputError
from shm_ros.ros.registry import KINDS, RESPAWN_DELAY_S
from shm_ros.ros.registry import node_kind as registry_entry


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
    # the ROS 2 parameters file the graph came from
    params_file: str | None = None
    namespace: str = ""  # e.g. "/bridge_a": every node, topic and service of the graph under it


@dataclass(frozen=True)
class NodeLaunch:
    """One node to start: what the launch file's ``Node(...)`` and the supervisor's process get."""

    name: str
    kind: str
    executable: str  # console script (``ros2 run shm_ros <executable>``)
    module: str  # ``python -m <module>`` runs the same node
    namespace: str
    parameters: dict[str, Any]
    respawn: bool
    respawn_delay_s: float


def normal_namespace(namespace: str) -> str:
    """``"a"`` / ``"/a/"`` -> ``"/a"``; ``""`` and ``"/"`` -> ``""`` (the root namespace)."""
    ns = "/" + namespace.strip().strip("/")
    return "" if ns == "/" else ns


def node_kind(name: str, source: str) -> str:
    """The node kind a node name starts with: ``identify`` and ``identify_data`` are identify nodes."""
    for kind in sorted(KINDS, key=len, reverse=True):
        if name == kind or name.startswith(kind + "_"):
            return kind
    raise ConfigError(f"{source}: {name}: a node's name must start with its kind ({', '.join(KINDS)})")


def launch_plan(config: GraphConfig, autostart: bool = True) -> list[NodeLaunch]:
    """The nodes to start for ``config``; ``autostart`` false leaves every node unconfigured for a
    lifecycle manager to bring up."""
    out = []
    for node in config.nodes:
        entry = registry_entry(node.kind)
        out.append(NodeLaunch(node.name, node.kind, entry.executable, entry.module, config.namespace,
                              {**node.parameters, "autostart": autostart}, entry.respawn and config.restart,
                              RESPAWN_DELAY_S))
    return out


def load_graph_config(path_or_dict: str | Path | dict, *, mode: str | None = None,
                      restart: bool | None = None, namespace: str | None = None) -> GraphConfig:
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
        config = GraphConfig(_ros_parameters_file(raw, source), source=source)
        config.params_file = None if isinstance(path_or_dict, dict) else str(Path(path_or_dict).resolve())
    if mode is not None:
        config.mode = mode
    if restart is not None:
        config.restart = restart
    if namespace is not None:
        config.namespace = normal_namespace(namespace)
    if config.mode not in ("processes", "single"):
        raise ConfigError(f"{source}: graph mode must be 'processes' or 'single', not {config.mode!r}")
    return config


def _ros_parameters_file(raw: dict, source: str) -> list[NodeSpec]:
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
    return nodes


def _legacy(raw: dict, source: str) -> GraphConfig:
    graph = raw.get("graph", {}) or {}
    nodes = []
    for name, spec in (raw.get("nodes") or {}).items():
        spec = spec or {}
        kind = spec.get("kind", name)
        if kind not in KINDS:
            raise ConfigError(f"{source}: nodes.{name}.kind: unknown node kind {kind!r} "
                              f"(known: {', '.join(KINDS)})")
        params = spec.get("parameters", {}) or {}
        if not isinstance(params, dict):
            raise ConfigError(f"{source}: nodes.{name}.parameters must be a mapping")
        nodes.append(NodeSpec(name, kind, params))
    if not nodes:
        raise ConfigError(f"{source}: no nodes")
    return GraphConfig(nodes, graph.get("mode", "processes"), bool(graph.get("restart", True)),
                       int(graph.get("max_restarts", 5)), source)
