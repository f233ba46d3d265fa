"""identify: ``Window`` in, ``ModalEstimate`` out, through :func:`shm_ros.core.identify.identify_window`."""

from __future__ import annotations

import time
from typing import Any

from rclpy.node import Node

from shm_ros.core import ssi
from shm_ros.core.identify import METHODS, IdentifyConfig, identify_window
from shm_ros.ros import topics
from shm_ros.ros.convert import estimate_to_msg, window_from_msg
from shm_ros.ros.diagnostics import Diagnostics
from shm_ros.ros.node_main import overrides, spin
from shm_ros.ros.qos import stream_qos


class IdentifyNode(Node):
    def __init__(self, name: str = "identify", parameters: dict[str, Any] | None = None) -> None:
        super().__init__(name, parameter_overrides=overrides(parameters))
        defaults = IdentifyConfig()
        self.declare_parameter("method", defaults.method)
        self.declare_parameter("max_order", defaults.max_order)
        self.declare_parameter("order_step", defaults.order_step)
        self.declare_parameter("reference_channels", [""])
        self.declare_parameter("uncertainty", False)
        self.declare_parameter("weighting", defaults.weighting)  # SSI-data: pc | upc | cva
        self.declare_parameter("frame_id", "")
        get = lambda n: self.get_parameter(n).value  # noqa: E731
        method = str(get("method"))
        if method not in METHODS:
            raise SystemExit(f"identify: parameter 'method' must be one of {METHODS}, not {method!r}")
        weighting = str(get("weighting"))
        if weighting not in ssi.WEIGHTINGS:
            raise SystemExit(f"identify: parameter 'weighting' must be one of {ssi.WEIGHTINGS}, "
                             f"not {weighting!r}")
        refs = [r for r in get("reference_channels") if r]
        self.config = IdentifyConfig(method=method, max_order=int(get("max_order")),
                                     order_step=int(get("order_step")),
                                     reference_channels=refs or None,
                                     uncertainty=bool(get("uncertainty")), weighting=weighting)
        self.frame_id = str(get("frame_id"))
        self.diag = Diagnostics(self, "identify")
        self.pub = self.create_publisher(topics.message_class(topics.TYPES[topics.MODAL_ESTIMATES]),
                                         topics.MODAL_ESTIMATES, stream_qos())
        self.create_subscription(topics.message_class(topics.TYPES[topics.WINDOWS]), topics.WINDOWS,
                                 self._on_window, stream_qos())
        self.count = 0
        self.get_logger().info(f"identify with {method}, orders up to {self.config.max_order}")

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
