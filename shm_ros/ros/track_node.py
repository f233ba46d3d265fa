"""track: modal estimates in, tracked modes out (one ``TrackedModes`` per window).

Thin adapter over :class:`shm_ros.core.tracking.Tracker`: the first ``reference_windows``
estimates establish the tracked modes (then their rows are published at once), the first
``training_windows`` rows the environmental model and the novelty threshold; a novelty alarm is
also a WARN diagnostic.
"""

from __future__ import annotations

from typing import Any

from rclpy.node import Node

from shm_ros.core.tracking import Tracker, TrackingConfig
from shm_ros.ros import topics
from shm_ros.ros.convert import estimate_from_msg, tracked_row_to_msg
from shm_ros.ros.diagnostics import Diagnostics
from shm_ros.ros.node_main import overrides, spin
from shm_ros.ros.qos import stream_qos


class TrackNode(Node):
    def __init__(self, name: str = "track", parameters: dict[str, Any] | None = None) -> None:
        super().__init__(name, parameter_overrides=overrides(parameters))
        d = TrackingConfig()
        for key, value in (("reference_windows", d.reference_windows), ("min_presence", d.min_presence),
                           ("freq_tol", d.freq_tol), ("mac_min", d.mac_min), ("adapt", d.adapt),
                           ("covariate", d.covariate), ("alarm_quantile", d.alarm_quantile),
                           ("training_windows", 144), ("frame_id", "")):
            self.declare_parameter(key, value)
        get = lambda n: self.get_parameter(n).value  # noqa: E731
        try:
            cfg = TrackingConfig(reference_windows=int(get("reference_windows")),
                                 min_presence=float(get("min_presence")),
                                 freq_tol=float(get("freq_tol")), mac_min=float(get("mac_min")),
                                 adapt=float(get("adapt")), covariate=str(get("covariate")),
                                 alarm_quantile=float(get("alarm_quantile")))
            self.tracker = Tracker(cfg, training_windows=int(get("training_windows")))
        except ValueError as exc:
            raise SystemExit(f"track: parameter error: {exc}") from exc
        self.frame_id = str(get("frame_id"))
        self.diag = Diagnostics(self, "track")
        self.pub = self.create_publisher(topics.message_class(topics.TYPES[topics.TRACKED_MODES]),
                                         topics.TRACKED_MODES, stream_qos())
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
