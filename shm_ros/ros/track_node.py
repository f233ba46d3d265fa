"""track: modal estimates in, tracked modes out (one ``TrackedModes`` per window).

Thin adapter over :class:`shm_ros.core.tracking.Tracker`: the first ``reference_windows``
estimates establish the tracked modes (then their rows are published at once), the first
``training_windows`` rows the environmental model and the novelty threshold; a novelty alarm is
also a WARN diagnostic.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from rclpy.node import Node
from rclpy.publisher import Publisher

from shm_ros.core.config import option
from shm_ros.core.tracking import Tracker, TrackingConfig
from shm_ros.ros import topics
from shm_ros.ros.convert import estimate_from_msg, tracked_row_to_msg
from shm_ros.ros.diagnostics import Diagnostics
from shm_ros.ros.node_main import overrides, spin
from shm_ros.ros.params import load_config
from shm_ros.ros.qos import stream_qos


@dataclass
class TrackNodeConfig:
    """Settings of the node itself (the tracking's are :class:`TrackingConfig`; its
    ``training_fraction`` is for a whole campaign offline, the node counts windows instead)."""

    training_windows: int = option(144, "first rows that train the environmental model and the "
                                   "novelty threshold (144: one day of 10-minute windows)")
    frame_id: str = option("", "frame_id in the header of the published tracked modes")


class TrackNode(Node):
    """Parameters: the options of :class:`TrackingConfig` offered to nodes and of
    :class:`TrackNodeConfig`."""

    def __init__(self, name: str = "track", parameters: dict[str, Any] | None = None) -> None:
        super().__init__(name, parameter_overrides=overrides(parameters))
        cfg = load_config(self, TrackingConfig)
        settings = load_config(self, TrackNodeConfig)
        try:
            self.tracker = Tracker(cfg, training_windows=settings.training_windows)
        except ValueError as exc:
            raise SystemExit(f"{self.get_name()}: parameter error: {exc}") from exc
        self.frame_id = settings.frame_id
        self.diag = Diagnostics(self, "track", summary=lambda: (
            "ok", f"{self.published} windows tracked", {"windows": self.published}))
        self.pub: Publisher[Any] = self.create_publisher(
            topics.message_class(topics.TYPES[topics.TRACKED_MODES]), topics.TRACKED_MODES,
            stream_qos())
        self.create_subscription(topics.message_class(topics.TYPES[topics.MODAL_ESTIMATES]),
                                 topics.MODAL_ESTIMATES, self._on_estimate, stream_qos())
        self.published = 0
        self.get_logger().info(f"track: reference from the first {cfg.reference_windows} windows")

    def _on_estimate(self, msg) -> None:
        source = f"{topics.MODAL_ESTIMATES}[{msg.window_id}]"
        try:
            rows = self.tracker.add(estimate_from_msg(msg))
        except Exception as exc:  # one bad estimate must never take the node down
            self.diag.report("error", f"estimate not tracked: {exc}", source)
            self.diag.publish()
            return
        for row in rows:
            self.pub.publish(tracked_row_to_msg(row, self.frame_id))
            self.published += 1
            found = int((row.frequencies_hz == row.frequencies_hz).sum())
            text = f"{found} of {len(row.mode_numbers)} tracked modes"
            if row.novelty_alarm:
                self.diag.report("warn", f"novelty alarm: score {row.novelty_score:.2f} above "
                                 f"{row.novelty_threshold:.2f}; {text}",
                                 f"{topics.TRACKED_MODES}[{row.window_id}]")
            else:
                self.diag.report("ok", text, f"{topics.TRACKED_MODES}[{row.window_id}]",
                                 novelty_score=f"{row.novelty_score:.3g}")
        if rows:
            self.diag.publish()
            if len(rows) > 1:
                freqs = ", ".join(f"{r.frequency_hz:.3f}" for r in self.tracker.reference)
                self.get_logger().info(f"tracked modes at [{freqs}] Hz")


def make_node(name: str, parameters: dict[str, Any]) -> TrackNode:
    return TrackNode(name, parameters)


def main(args: list[str] | None = None) -> int:
    return spin(lambda: TrackNode(), args)


if __name__ == "__main__":
    raise SystemExit(main())
