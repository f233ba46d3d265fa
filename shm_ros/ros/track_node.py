"""track: modal estimates in, tracked modes out (one ``TrackedModes`` per window), with history.

Thin adapter over :class:`shm_ros.core.tracking.Tracker` and the history store
(:mod:`shm_ros.io.store`, SQLite): each estimate is tracked and stored with its row in one
transaction, then the row is published; a novelty alarm is also published on the latched
``shm/tracking_alarms`` (the alarm window's row, its ``mode_numbers`` the modes that moved) and
is a WARN diagnostic.

Restart: the node resumes from the store (checkpoint + replay of the estimates stored after it).
Estimates published while it was down are recovered from the identify node's publisher, whose
modal estimates are transient-local with a history of ``qos.PIPELINE_DEPTH`` (100 windows, about
17 hours of 10-minute windows): on rematching, the publisher sends them again, and those whose
window is already in the store are skipped, so nothing is lost or counted twice. A longer outage
loses the windows beyond that history (re-run ``shm-ros identify`` on the bag for them).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rclpy.publisher import Publisher

from shm_ros.core.config import option
from shm_ros.core.tracking import Tracker, TrackingConfig
from shm_ros.io.atomic import DiskFullError
from shm_ros.ros import topics
from shm_ros.ros.convert import estimate_from_msg, tracked_row_to_msg
from shm_ros.ros.managed import ManagedNode
from shm_ros.ros.node_main import spin
from shm_ros.ros.params import ParameterError, load_config
from shm_ros.ros.qos import latched_qos, stream_qos

ALARM_HISTORY = 20  # latched alarms a late joiner receives


@dataclass
class TrackNodeConfig:
    """Settings of the node itself (the tracking's are :class:`TrackingConfig`; its
    ``training_fraction`` is for a whole campaign offline, the node counts windows instead)."""

    training_windows: int = option(144, "first rows that train the environmental model and the "
                                   "novelty threshold (144: one day of 10-minute windows)")
    frame_id: str = option("", "frame_id in the header of the published tracked modes")
    store: str = option("", "history store (SQLite); empty: $ROS_HOME/shm_ros/track.sqlite (ROS_HOME "
                        "defaults to ~/.ros); none: no store, no resume", cli=False)
    retention_days: float = option(0.0, "store: delete windows older than this before the newest (0 = keep all)")
    checkpoint_every: int = option(100, "store: windows between checkpoints of the tracker (a restart "
                                   "replays at most this many)")
    # the command's --store (a store to export) and --structure are its own options
    structure: str = option("", "structure file whose FE modes seed the reference (reference_source model/both)",
                            cli=False)


def default_store() -> Path:
    return Path(os.environ.get("ROS_HOME", Path.home() / ".ros")) / "shm_ros" / "track.sqlite"


class TrackNode(ManagedNode):
    """Parameters: the options of :class:`TrackingConfig` offered to nodes and of
    :class:`TrackNodeConfig`."""

    kind = "track"

    def setup(self) -> None:
        cfg = load_config(self, TrackingConfig)
        settings = load_config(self, TrackNodeConfig)
        self.store = None
        replayed = 0
        try:
            spec = None
            if settings.structure:
                from shm_ros.io.structure import load_structure

                spec = load_structure(settings.structure)

            def fresh() -> Tracker:
                return Tracker(cfg, training_windows=settings.training_windows, structure=spec)

            self.tracker = fresh()
            if settings.store.lower() != "none":
                from shm_ros.io.store import TrackStore, resume

                path = Path(settings.store) if settings.store else default_store()
                self.store = TrackStore(path, retention_days=settings.retention_days,
                                        checkpoint_every=settings.checkpoint_every)
                self.tracker, replayed = resume(self.store, fresh)
        except (ValueError, OSError, RuntimeError) as exc:
            raise ParameterError(f"{self.get_name()}: parameter error: {exc}") from exc
        self.frame_id = settings.frame_id
        self.published = self.store.count("rows") if self.store is not None else 0
        self.duplicates = 0
        self.diag.summarize(lambda: (
            "ok", f"{self.published} windows tracked", {"windows": self.published,
                                                        "duplicates_skipped": self.duplicates}))
        msg_type = topics.message_class(topics.TYPES[topics.TRACKED_MODES])
        self.pub: Publisher[Any] = self.create_publisher(msg_type, topics.TRACKED_MODES, stream_qos())
        self.alarm_pub: Publisher[Any] = self.create_publisher(msg_type, topics.TRACKING_ALARMS,
                                                               latched_qos(ALARM_HISTORY))
        self.create_subscription(topics.message_class(topics.TYPES[topics.MODAL_ESTIMATES]),
                                 topics.MODAL_ESTIMATES, self._on_estimate, stream_qos())
        where = f"; store {self.store.path} ({self.published} windows, {replayed} replayed)" if self.store else ""
        self.get_logger().info(f"track: reference from the first {cfg.reference_windows} windows{where}")

    def _on_estimate(self, msg) -> None:
        source = f"{topics.MODAL_ESTIMATES}[{msg.window_id}]"
        if self.store is not None and self.store.has(msg.window_id):
            # already tracked (redelivered after a restart, or the same recording replayed again):
            # not tracked twice, but its stored row goes out again, so that a second replay of a bag
            # feeds update and explain as the first did (they keep one row per window)
            self.duplicates += 1
            row = self.store.row(msg.window_id)
            if row is not None:
                self.pub.publish(tracked_row_to_msg(row, self.frame_id))
            if self.duplicates == 1:
                self.diag.report("ok", f"window {msg.window_id} already in the store {self.store.path}: its "
                                 "stored row re-published, not tracked again (store: none to start afresh)",
                                 source)
                self.diag.publish()
            return
        try:
            est = estimate_from_msg(msg)
            rows = self.tracker.add(est)
            if self.store is not None:
                self.store.record(est, rows, self.tracker)
        except DiskFullError:  # not one bad estimate: the store cannot take more; the node stops
            raise
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
                alarm = tracked_row_to_msg(row, self.frame_id)
                keep = [k for k, n in enumerate(row.mode_numbers) if n in row.alarm_modes]
                alarm.mode_numbers = [int(row.mode_numbers[k]) for k in keep]
                alarm.frequencies_hz = [float(row.frequencies_hz[k]) for k in keep]
                alarm.damping_ratios = [float(row.damping[k]) for k in keep]
                alarm.macs_to_reference = [float(row.macs[k]) for k in keep]
                alarm.mode_shapes = [float(v) for k in keep for v in row.shapes[k]]
                self.alarm_pub.publish(alarm)
                self.diag.report("warn", f"novelty alarm: score {row.novelty_score:.2f} above "
                                 f"{row.novelty_threshold:.2f}, modes {row.alarm_modes}; {text}",
                                 f"{topics.TRACKED_MODES}[{row.window_id}]")
            else:
                self.diag.report("ok", text, f"{topics.TRACKED_MODES}[{row.window_id}]",
                                 novelty_score=f"{row.novelty_score:.3g}")
        if rows:
            self.diag.publish()
            if len(rows) > 1:
                freqs = ", ".join(f"{r.frequency_hz:.3f}" for r in self.tracker.reference)
                self.get_logger().info(f"tracked modes at [{freqs}] Hz")

    def teardown(self) -> None:
        if self.store is not None:
            self.store.close()


def make_node(name: str, parameters: dict[str, Any], namespace: str = "") -> TrackNode:
    return TrackNode(name, parameters, namespace)


def main(args: list[str] | None = None) -> int:
    return spin(lambda: TrackNode(), args)


if __name__ == "__main__":
    raise SystemExit(main())
