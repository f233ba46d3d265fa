"""identify: ``Window`` in, ``ModalEstimate`` out, through :func:`shm_ros.core.identify.identify_window`."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

from rclpy.node import Node
from rclpy.publisher import Publisher

from shm_ros.core.config import option
from shm_ros.core.identify import IdentifyConfig, identify_window
from shm_ros.ros import topics
from shm_ros.ros.convert import estimate_to_msg, window_from_msg
from shm_ros.ros.diagnostics import Diagnostics
from shm_ros.ros.node_main import overrides, spin
from shm_ros.ros.params import load_config
from shm_ros.ros.qos import stream_qos


@dataclass
class IdentifyNodeConfig:
    """Settings of the node itself (the identification's are :class:`IdentifyConfig`)."""

    frame_id: str = option("", "frame_id in the header of the published estimates")


class IdentifyNode(Node):
    """Parameters: every option of :class:`IdentifyConfig` (``preprocess.*``, ``stability.*`` and
    ``picking.*`` for its nested configurations) and of :class:`IdentifyNodeConfig`."""

    def __init__(self, name: str = "identify", parameters: dict[str, Any] | None = None) -> None:
        super().__init__(name, parameter_overrides=overrides(parameters))
        self.config = load_config(self, IdentifyConfig)
        self.frame_id = load_config(self, IdentifyNodeConfig).frame_id
        self.diag = Diagnostics(self, "identify", summary=lambda: (
            "ok", f"{self.count} windows identified", {"windows": self.count}))
        self.pub: Publisher[Any] = self.create_publisher(
            topics.message_class(topics.TYPES[topics.MODAL_ESTIMATES]), topics.MODAL_ESTIMATES,
            stream_qos())
        self.create_subscription(topics.message_class(topics.TYPES[topics.WINDOWS]), topics.WINDOWS,
                                 self._on_window, stream_qos())
        self.count = 0
        self.get_logger().info(f"identify with {self.config.method}, orders up to {self.config.max_order}"
                               + ("" if self.config.uncertainty else ", no uncertainty"))

    def _on_window(self, msg) -> None:
        t0 = time.perf_counter()
        try:
            estimate = identify_window(window_from_msg(msg), self.config)
        except Exception as exc:  # one bad window must never take the node down
            self.diag.report("error", f"window not identified: {exc}", f"{topics.WINDOWS}[{msg.window_id}]")
            self.diag.publish()
            return
        self.pub.publish(estimate_to_msg(estimate, self.frame_id))
        self.count += 1
        freqs = ", ".join(f"{m.frequency_hz:.3f}" for m in estimate.modes)
        self.diag.report("ok", f"{len(estimate.modes)} modes in {time.perf_counter() - t0:.2f} s",
                         f"{topics.WINDOWS}[{msg.window_id}]", frequencies_hz=freqs)
        self.diag.publish()
        self.get_logger().info(f"window {msg.window_id}: modes at [{freqs}] Hz")


def make_node(name: str, parameters: dict[str, Any]) -> IdentifyNode:
    return IdentifyNode(name, parameters)


def main(args: list[str] | None = None) -> int:
    return spin(lambda: IdentifyNode(), args)


if __name__ == "__main__":
    raise SystemExit(main())
