"""ingest: recording topics in, validated and aligned ``Window`` messages out.

Subscribes (sensor-data QoS, deep history) to ``<prefix>/accel/<id>`` (sensor_msgs/Imu),
``<prefix>/accel_block`` (shm_interfaces/AccelBlock) and ``<prefix>/temperature/<id>``
(sensor_msgs/Temperature) as they appear in the graph (ROS has no wildcard subscriptions, so the
graph is polled), those under the node's namespace when it has one; all science is in
:class:`shm_ros.core.ingest.IngestCore`, which this node feeds with arrays (stamps in ns,
accelerations per axis) decoded from the messages.
Publishes ``shm/windows``, ``/diagnostics`` and ``shm/ingest/received`` (flow control for replay),
relative to the node's namespace (docs/topics.md). A managed node (:mod:`shm_ros.ros.managed`):
a bad structure file fails ``configure`` with the file and field.

Sensors and topics that do not fit together are reported up front (a WARN diagnostic and a
warning on the terminal): an accelerometer topic that feeds no structure sensor as soon as it is
discovered, a structure sensor that no topic feeds once ``discovery_timeout_s`` has passed (topics
of a live graph appear over time), each with the closest names.
"""

from __future__ import annotations

import os
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
from rclpy.duration import Duration
from std_msgs.msg import String, UInt64

from shm_ros.core.config import option
from shm_ros.core.diagnostics import Diagnostic, Level
from shm_ros.core.ingest import ChannelMap, IngestConfig, IngestCore, channel_mismatches
from shm_ros.io.bags import ACCEL_BLOCK, IMU, TEMPERATURE, topic_kind
from shm_ros.io.faults import fault_point
from shm_ros.io.imu_cdr import decode_imu_batch
from shm_ros.ros import topics
from shm_ros.ros.convert import time_to_ns, window_to_msg
from shm_ros.ros.managed import ManagedNode
from shm_ros.ros.node_main import spin
from shm_ros.ros.params import ParameterError, load_config
from shm_ros.ros.qos import WINDOW_HISTORY, latched_qos, pipeline_qos, recording_qos, stream_qos
from shm_ros.ros.timers import steady_timer

IMU_BATCH = 512  # Imu messages decoded together (also every 0.05 s)
MAX_HELD_WINDOWS = 64  # windows held for a slow reader before they go out regardless
HOLD_ACKS_AT = 2  # more windows held than this: the replay's acknowledgements wait


@dataclass
class IngestNodeConfig:
    """Settings of the node itself (the windowing's are :class:`IngestConfig`)."""

    structure: str | None = option(None, "path of the structure YAML (required)")
    reliable_input: bool = option(False, "subscribe to recording topics reliable (default: best effort, "
                                  "which also matches reliable publishers)")
    idle_flush_s: float = option(5.0, "wall-clock seconds without input after which the data held is "
                                 "cut into windows")
    discovery_period_s: float = option(0.5, "how often the graph is searched for new recording topics, s")
    discovery_timeout_s: float = option(10.0, "a structure sensor that no topic feeds this long after "
                                        "start is reported, s")
    frame_id: str = option("", "frame_id in the header of the published windows")
    close_wait_s: float = option(10.0, "on shutdown, how long the windows still held wait for a slow reader, s "
                                 "(a reader whose process died is waited for in vain until DDS drops it)")


class IngestNode(ManagedNode):
    """Parameters: the options of :class:`IngestConfig` and of :class:`IngestNodeConfig`."""

    kind = "ingest"

    def setup(self) -> None:
        config = load_config(self, IngestConfig)
        settings = load_config(self, IngestNodeConfig)
        self.core = IngestCore(self._channel_map(settings.structure), config)
        self.frame_id = settings.frame_id
        self.idle_flush_s = settings.idle_flush_s
        if not settings.close_wait_s >= 0.0:  # NaN too
            raise ParameterError(f"{self.get_name()}: parameter 'close_wait_s' must be >= 0, "
                                 f"got {settings.close_wait_s}")
        self.close_wait_s = settings.close_wait_s
        self.reliable = settings.reliable_input
        # window_readers: subscriptions this node's window publisher has matched (a reader that the
        # graph shows but that is not matched yet would miss the first windows)
        self.diag.summarize(lambda: (
            "ok", f"{self.received} messages received, {self.windows_out} windows published",
            {"messages": self.received, "windows": self.windows_out,
             "window_readers": self.window_pub.get_subscription_count(),
             "windows_unawaited": self.windows_unawaited}))
        self.window_pub: Any = self.create_publisher(
            topics.message_class(topics.TYPES[topics.WINDOWS]), topics.WINDOWS, stream_qos(WINDOW_HISTORY))
        self.ack_pub = self.create_publisher(UInt64, topics.INGEST_RECEIVED, pipeline_qos())
        self.create_subscription(String, topics.REPLAY_DONE, self._on_replay_done, latched_qos())
        self.pending: deque[Any] = deque()  # windows held until the readers took the previous one
        self.ack_hold = 0
        self.subscribed: set[str] = set()
        self.accel_topics: set[str] = set()
        self.temperature_topics: set[str] = set()
        self.block_topics: set[str] = set()
        self.block_channels: set[str] = set()
        self.discovery_timeout_s = settings.discovery_timeout_s
        self.started = time.monotonic()
        self.sensors_checked = False
        self._imu_raw: dict[str, tuple[str, list[bytes]]] = {}
        self._imu_raw_n = 0
        self.received = 0
        self.acked = -1
        self.windows_out = 0
        # windows published without waiting for a slow reader (MAX_HELD_WINDOWS held already): the
        # drop policy's counter, on /diagnostics
        self.windows_unawaited = 0
        self.last_stamp_ns: int | None = None
        self.last_msg_wall = time.monotonic()
        steady_timer(self, settings.discovery_period_s, self._discover)
        steady_timer(self, 0.05, self._on_ack_timer)
        # The count also goes out when it does not change, so that a replay started later learns
        # where the count stands before it counts its own messages (its flow control needs that).
        steady_timer(self, 0.5, self._heartbeat)
        steady_timer(self, 1.0, self._idle)
        self._discover()
        self.get_logger().info(f"ingest for sensors {self.core.channels}")

    def _channel_map(self, structure: str | None) -> ChannelMap:
        if not structure:
            raise ParameterError(f"{self.get_name()}: parameter 'structure' (path of the structure YAML) is required")
        from shm_ros.io.structure import load_structure

        return ChannelMap.from_structure(load_structure(structure))

    # -- topics appear while the graph runs: subscribe to the recording topics ----------------------
    def _discover(self) -> None:
        qos = recording_qos(reliable=self.reliable)
        # in a namespace, only the recording topics under it: another graph's are not this structure's
        ns = self.get_namespace().rstrip("/")
        for topic, types in self.get_topic_names_and_types():
            if topic in self.subscribed or not topic.startswith(ns + "/"):
                continue
            for msgtype in types:
                kind = topic_kind(topic, msgtype)
                if kind is None:
                    continue
                callback = {"block": self._on_block, "temperature": self._on_temperature}.get(kind[0])
                cls = topics.message_class({"imu": IMU, "block": ACCEL_BLOCK,
                                            "temperature": TEMPERATURE}[kind[0]])
                # a block carries many samples: acknowledged at once, so that a flow-controlled
                # replay of blocks is not held to the acknowledgement timer
                ack_every = 1 if kind[0] == "block" else 50
                if kind[0] == "imu":  # one sample per message: CDR bytes, decoded in batches
                    self.create_subscription(cls, topic, self._imu_raw_handler(topic, kind[1]), qos,
                                             raw=True)
                else:
                    self.create_subscription(cls, topic, self._guard(topic, callback, kind[1], ack_every),
                                             qos)
                self.subscribed.add(topic)
                self.get_logger().info(f"subscribed to {topic} ({msgtype})")
                if kind[0] == "imu":
                    self.accel_topics.add(topic)
                    self._report_mismatches([topic], "unknown_topic")
                elif kind[0] == "temperature":
                    self.temperature_topics.add(topic)
                elif kind[0] == "block":
                    self.block_topics.add(topic)
        # block channel names are known from the first block only: wait for it when there is a block topic
        blocks_known = bool(self.block_channels) or not self.block_topics
        if not self.sensors_checked and blocks_known and time.monotonic() - self.started >= self.discovery_timeout_s:
            self.sensors_checked = True
            self._report_mismatches(sorted(self.accel_topics), "sensor_unmatched")

    def _report_mismatches(self, accel_topics: list[str], code: str) -> None:
        """Report what ``channel_mismatches`` finds of one kind, on the terminal and /diagnostics."""
        found = channel_mismatches(self.core.map, accel_topics, sorted(self.temperature_topics),
                                   sorted(self.block_channels))
        self._publish_diagnostics([d for d in found if d.code == code])

    def _guard(self, topic: str, callback, sensor_id: str, ack_every: int = 50):
        def handle(msg) -> None:
            self.received += 1
            self.last_msg_wall = time.monotonic()
            try:
                callback(msg, sensor_id, topic)
            except Exception as exc:  # one bad message must never take the node down
                self.core.report_error(topic, f"message not processed: {exc!r}")
            try:
                self._emit()
            except Exception as exc:  # nor a failure to publish what came out of it
                self.get_logger().error(f"{topic}: output not published: {exc!r}")
            if self.received - self.acked >= ack_every:
                self._ack()
        return handle

    def _imu_raw_handler(self, topic: str, sensor_id: str):
        """Per-sample Imu: the CDR bytes are kept and decoded in batches with numpy
        (``decode_imu_batch``), then fed with ``add_accel``; building a Python message
        object per sample (three covariance arrays) cost more than everything else here."""
        pending = self._imu_raw.setdefault(topic, (sensor_id, []))[1]

        def handle(data: bytes) -> None:
            self.received += 1
            self.last_msg_wall = time.monotonic()
            pending.append(data)
            self._imu_raw_n += 1
            if self._imu_raw_n >= IMU_BATCH:
                self._feed_imu()
            if self.received - self.acked >= 50:
                self._ack()
        return handle

    def _feed_imu(self) -> None:
        """Decode and feed the Imu messages taken so far; publish what comes out."""
        if not self._imu_raw_n:
            return
        self._imu_raw_n = 0
        for topic, (sensor_id, datas) in self._imu_raw.items():
            if not datas:
                continue
            batch = list(datas)
            datas.clear()
            try:
                try:
                    stamps, xyz = decode_imu_batch(batch)
                except ValueError:  # a malformed message: find it, keep the others
                    good = []
                    for data in batch:
                        try:
                            good.append(decode_imu_batch([data]))
                        except ValueError as exc:
                            self.core.report_error(topic, f"malformed Imu message not processed: {exc}")
                    if not good:
                        continue
                    stamps = np.concatenate([g[0] for g in good])
                    xyz = np.concatenate([g[1] for g in good])
                self.core.add_accel(sensor_id, stamps, xyz, field="linear_acceleration")
                t = int(stamps.max())
                self.last_stamp_ns = max(self.last_stamp_ns or t, t)
            except Exception as exc:  # one bad batch must never take the node down
                self.core.report_error(topic, f"messages not processed: {exc!r}")
        try:
            self._emit()
        except Exception as exc:
            self.get_logger().error(f"output not published: {exc!r}")

    def _on_block(self, msg, _sensor_id: str, topic: str) -> None:
        t = time_to_ns(msg.header.stamp)
        self.block_channels.update(msg.channel_names)
        samples = np.frombuffer(msg.samples, dtype=np.float64) if len(msg.samples) else np.zeros(0)
        self.core.add_block(t, msg.sample_rate_hz, list(msg.channel_names), samples, msg.units, topic)
        if msg.sample_rate_hz > 0 and len(msg.channel_names):
            end = t + int(samples.size / len(msg.channel_names) * 1e9 / msg.sample_rate_hz)
            self.last_stamp_ns = max(self.last_stamp_ns or end, end)

    def _on_temperature(self, msg, sensor_id: str, topic: str) -> None:
        self.core.add_temperature(sensor_id, time_to_ns(msg.header.stamp), msg.temperature,
                                  source=f"temperature/{sensor_id}.temperature")

    # -- outputs -------------------------------------------------------------------------------
    def _emit(self, windows: list | None = None) -> None:
        self.pending.extend(self.core.pop_windows() if windows is None else windows)
        self._release_windows()
        self._publish_diagnostics(self.core.pop_diagnostics())

    def _release_windows(self, wait_s: float = 0.0) -> None:
        """Publish held windows one at a time, each once every reliable reader has acknowledged
        the previous one. The publisher keeps only the last few windows (they are large), so a
        reader that falls behind (identify on a busy machine) would otherwise lose windows; while
        windows are held, the replay's acknowledgements are held too (back-pressure to the bag)."""
        while self.pending:
            if not self.window_pub.wait_for_all_acked(Duration(nanoseconds=int(wait_s * 1e9))):
                if len(self.pending) <= MAX_HELD_WINDOWS:
                    return
                self.windows_unawaited += 1
                self.diag.report("warn", f"{len(self.pending)} windows waiting for a slow reader: "
                                 "publishing without waiting (the slowest reader may miss some; "
                                 f"{self.windows_unawaited} so far)", topics.WINDOWS,
                                 windows_unawaited=self.windows_unawaited)
            window = self.pending.popleft()
            self.window_pub.publish(window_to_msg(window, self.frame_id))
            self.windows_out += 1
            fault_point(self.get_name(), "published")
            self.get_logger().info(f"window {window.window_id}: {window.n_samples} samples x "
                                   f"{len(window.channel_names)} channels")

    def _publish_diagnostics(self, diagnostics: list[Diagnostic]) -> None:
        for d in diagnostics:
            self.diag.report(Level(d.level), d.message, d.source, code=d.code, count=d.count)
        self.diag.publish()

    def _on_ack_timer(self) -> None:
        self._feed_imu()
        self._release_windows()
        self._ack()

    def _ack_count(self) -> int:
        """Messages acknowledged to the replay: all received, unless more than ``HOLD_ACKS_AT``
        windows are held for a slow reader (then the count stands still and a flow-controlled
        replay waits, so that held windows cannot pile up in memory; a window or two in flight
        does not hold the end of a replay)."""
        if len(self.pending) <= HOLD_ACKS_AT:
            self.ack_hold = self.received
        return self.ack_hold

    def _ack(self) -> None:
        count = self._ack_count()
        if count != self.acked:
            self.ack_pub.publish(UInt64(data=count))
            self.acked = count

    def _heartbeat(self) -> None:
        count = self._ack_count()
        self.ack_pub.publish(UInt64(data=count))
        self.acked = count

    def _idle(self) -> None:
        """No data for a while: let time advance on the stamp clock so finished bursts go out."""
        self._feed_imu()
        idle = time.monotonic() - self.last_msg_wall
        if self.last_stamp_ns is not None and idle >= self.idle_flush_s:
            self.core.tick(self.last_stamp_ns + int(idle * 1e9))
            self._emit()

    def _on_replay_done(self, msg: String) -> None:
        self._feed_imu()
        self._ack()
        self._emit(self.core.flush())
        self.get_logger().info(f"end of replay of {msg.data}: flushed")

    def close(self) -> None:
        self._feed_imu()
        self.pending.extend(self.core.flush())
        end = time.monotonic() + self.close_wait_s
        while self.pending and time.monotonic() < end:  # give a slow reader its last windows
            self._release_windows(wait_s=0.5)
        while self.pending:  # the rest without waiting: the node is going
            window = self.pending.popleft()
            self.window_pub.publish(window_to_msg(window, self.frame_id))
            self.windows_out += 1


def make_node(name: str, parameters: dict[str, Any], namespace: str = "") -> IngestNode:
    return IngestNode(name, parameters, namespace)


def _executor():
    """rclpy's EventsExecutor: about twice the per-message Imu throughput of the
    SingleThreadedExecutor (docs/benchmarks.md); ``SHM_INGEST_EXECUTOR=single`` falls back."""
    if os.environ.get("SHM_INGEST_EXECUTOR", "events") == "single":
        from rclpy.executors import SingleThreadedExecutor

        return SingleThreadedExecutor()
    from rclpy.experimental import EventsExecutor

    return EventsExecutor()


def main(args: list[str] | None = None) -> int:
    return spin(lambda: IngestNode(), args, _executor)


if __name__ == "__main__":
    raise SystemExit(main())
