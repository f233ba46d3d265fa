"""``/diagnostics`` publishing shared by every node (diagnostic_msgs/DiagnosticArray)."""

from __future__ import annotations

from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from shm_ros.core.diagnostics import Level


class Diagnostics:
    """Collects status entries of one node and publishes them as one DiagnosticArray."""

    def __init__(self, node: Any, hardware_id: str = "shm_ros") -> None:
        from shm_ros.ros.qos import pipeline_qos

        self._node = node
        self._pub = node.create_publisher(DiagnosticArray, "/diagnostics", pipeline_qos())
        self._hardware_id = hardware_id
        self._pending: list[DiagnosticStatus] = []

    def report(self, level: Level | str, message: str, name: str = "", **values: Any) -> None:
        """Queue one status; ``name`` says what it is about (a topic, a field, a stage)."""
        level = Level.parse(level)  # "ok" | "warn" | "error" | "stale" or a Level
        status = DiagnosticStatus(
            level=bytes([level]), name=f"{self._node.get_name()}: {name}" if name else self._node.get_name(),
            message=message[:500], hardware_id=self._hardware_id,
            values=[KeyValue(key=str(k), value=str(v)) for k, v in values.items()],
        )
        self._pending.append(status)
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
