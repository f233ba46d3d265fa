"""identify: ``Window`` in, ``ModalEstimate`` out, through :func:`shm_ros.core.identify.identify_window`."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

from rclpy.publisher import Publisher

from shm_ros.core.config import option
from shm_ros.core.identify import IdentifyConfig, identify_window
from shm_ros.errors import ShmError
from shm_ros.io.faults import fault_point
from shm_ros.ros import topics
from shm_ros.ros.convert import estimate_to_msg, window_from_msg
from shm_ros.ros.managed import ManagedNode
from shm_ros.ros.node_main import spin
from shm_ros.ros.params import ParameterError, load_config
from shm_ros.ros.qos import stream_qos


@dataclass
class IdentifyNodeConfig:
    """Settings of the node itself (the identification's are :class:`IdentifyConfig`)."""

    frame_id: str = option("", "frame_id in the header of the published estimates")
    structure: str | None = option(None, "path of the structure YAML: its nominal model sets the band "
                                   "of interest (band auto/model), as in `shm-ros identify`; unset: "
                                   "the band comes from each window's spectrum")


class IdentifyNode(ManagedNode):
    """Parameters: every option of :class:`IdentifyConfig` (``preprocess.*``, ``stability.*`` and
    ``picking.*`` for its nested configurations) and of :class:`IdentifyNodeConfig`."""

    kind = "identify"

    def setup(self) -> None:
        self.config = load_config(self, IdentifyConfig)
        settings = load_config(self, IdentifyNodeConfig)
        self.frame_id = settings.frame_id
        if settings.structure and not self.config.nominal_frequencies_hz:
            self._band_from(settings.structure)
        self.diag.summarize(lambda: (
            "ok", f"{self.count} windows identified", {"windows": self.count}))
        self.pub: Publisher[Any] = self.create_publisher(
            topics.message_class(topics.TYPES[topics.MODAL_ESTIMATES]), topics.MODAL_ESTIMATES,
            stream_qos())
        self.create_subscription(topics.message_class(topics.TYPES[topics.WINDOWS]), topics.WINDOWS,
                                 self._on_window, stream_qos())
        self.count = 0
        orders = self.config.max_order or "the method's default"
        self.get_logger().info(f"identify with {self.config.method}, orders up to {orders}"
                               + ("" if self.config.uncertainty else ", no uncertainty"))

    def _band_from(self, path: str) -> None:
        """The structure's nominal frequencies for the band of interest (docs/identify.md)."""
        from shm_ros.core.band import band_frequencies
        from shm_ros.io.structure import load_structure

        try:
            spec = load_structure(path)
        except ShmError as exc:  # StructureError names the file and field
            raise ParameterError(f"{self.get_name()}: parameter 'structure': {exc}") from exc
        freqs, why_not = band_frequencies(spec, self.config.band, self.config.band_modes)
        self.config.nominal_frequencies_hz = freqs
        if why_not:
            self.get_logger().warning(f"{path}: {why_not}")
        elif freqs:
            self.get_logger().info(f"band of interest from {path}: nominal modes at "
                                   + ", ".join(f"{f:.3g}" for f in freqs) + " Hz")

    def _on_window(self, msg) -> None:
        t0 = time.perf_counter()
        try:
            estimate = identify_window(window_from_msg(msg), self.config)
        except Exception as exc:  # one bad window must never take the node down
            self.diag.report("error", f"window not identified: {exc}", f"{topics.WINDOWS}[{msg.window_id}]")
            self.diag.publish()
            return
        self.pub.publish(estimate_to_msg(estimate, self.frame_id))
        fault_point(self.get_name(), "published")
        self.count += 1
        freqs = ", ".join(f"{m.frequency_hz:.3f}" for m in estimate.modes)
        self.diag.report("ok", f"{len(estimate.modes)} modes in {time.perf_counter() - t0:.2f} s",
                         f"{topics.WINDOWS}[{msg.window_id}]", frequencies_hz=freqs)
        self.diag.publish()
        self.get_logger().info(f"window {msg.window_id}: modes at [{freqs}] Hz")


def make_node(name: str, parameters: dict[str, Any], namespace: str = "") -> IdentifyNode:
    return IdentifyNode(name, parameters, namespace)


def main(args: list[str] | None = None) -> int:
    return spin(lambda: IdentifyNode(), args)


if __name__ == "__main__":
    raise SystemExit(main())
