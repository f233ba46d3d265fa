"""``/diagnostics`` publishing shared by every node (diagnostic_msgs/DiagnosticArray)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from shm_ros.core.diagnostics import Level

#: what a node says of itself on every heartbeat: level, message, key/values
Summary = Callable[[], tuple[Level | str, str, dict[str, Any]]]


def status_prefix(namespace: str) -> str:
    """What a node's status names start with in ``namespace``: ``"bridge_a/"``, ``""`` at the root."""
    ns = namespace.strip("/")
    return f"{ns}/" if ns else ""


class Diagnostics:
    """Collects status entries of one node and publishes them as one DiagnosticArray.

    With ``summary`` (or once :meth:`summarize` is called), the node also reports its state every
    ``heartbeat_s`` seconds (steady clock) under the name ``<node>: status``, so that a monitor sees
    every node of the graph, busy or idle (a silent node is a stale one). ``<node>`` is the node's
    name with its namespace (``bridge_a/ingest``; the root namespace adds nothing): ``/diagnostics``
    is global, shared by every graph on the domain."""

    def __init__(self, node: Any, hardware_id: str = "shm_ros", summary: Summary | None = None,
                 heartbeat_s: float = 2.0) -> None:
        from shm_ros.ros.qos import pipeline_qos
        from shm_ros.ros.topics import DIAGNOSTICS

        self._node = node
        self._pub = node.create_publisher(DiagnosticArray, DIAGNOSTICS, pipeline_qos())
        self._hardware_id = hardware_id
        self._pending: list[DiagnosticStatus] = []
        self._summary = summary
        if summary is not None:
            self.summarize(summary, heartbeat_s)

    def summarize(self, summary: Summary, heartbeat_s: float = 2.0) -> None:
        """Report ``summary()`` every ``heartbeat_s`` seconds from now on."""
        from shm_ros.ros.timers import steady_timer

        self._summary = summary
        steady_timer(self._node, heartbeat_s, self._heartbeat)

    def _heartbeat(self) -> None:
        assert self._summary is not None
        level, message, values = self._summary()
        self._pending.append(self._status(Level.parse(level), message, "status", values))
        self.publish()

    def _status(self, level: Level, message: str, name: str, values: dict[str, Any]) -> DiagnosticStatus:
        node = status_prefix(self._node.get_namespace()) + self._node.get_name()
        return DiagnosticStatus(
            level=bytes([level]), name=f"{node}: {name}" if name else node,
            message=message[:500], hardware_id=self._hardware_id,
            values=[KeyValue(key=str(k), value=str(v)) for k, v in values.items()])

    def report(self, level: Level | str, message: str, name: str = "", **values: Any) -> None:
        """Queue one status; ``name`` says what it is about (a topic, a field, a stage)."""
        level = Level.parse(level)  # "ok" | "warn" | "error" | "stale" or a Level
        self._pending.append(self._status(level, message, name, values))
        # rclpy refuses a call site that logs at changing severities ("Logger severity cannot be
        # changed between calls"): one call per severity.
        text = f"{name}: {message}" if name else message
        if level == Level.WARN:
            self._node.get_logger().warning(text)
        elif level != Level.OK:
            self._node.get_logger().error(text)

    def publish(self) -> None:
        if not self._pending:
            return
        msg = DiagnosticArray()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        msg.status = self._pending
        self._pub.publish(msg)
        self._pending = []
