"""Replay a rosbag2 bag through the running graph, in real time, xN, or as fast as it keeps up.

Messages are published as the CDR bytes stored in the bag (no decode/re-encode). Flow control: the
ingest node publishes how many recording messages it has taken (``shm/ingest/received``); with
``rate=0`` the replayer keeps at most ``credit`` messages and ``credit_bytes`` bytes in flight, so
neither the subscriber's history nor the transport's buffers overflow, and nothing is dropped even
on best-effort (sensor-data) subscriptions. Publishing flat out with KEEP_LAST would drop
silently once the subscriber lags.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import rclpy
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String, UInt64

from shm_ros.core.timeutil import split_ns
from shm_ros.io.bags import BagError, BagMessage, topic_kind
from shm_ros.io.sources import open_source
from shm_ros.ros import topics
from shm_ros.ros.qos import latched_qos, pipeline_qos


@dataclass
class ReplayResult:
    published: int = 0
    acknowledged: int = 0
    skipped_topics: dict[str, str] = field(default_factory=dict)
    wall_s: float = 0.0
    bag_span_s: float = 0.0
    started_ns: int = 0  # system clock at the first publish
    error: str = ""  # the bag could not be read to its end (what was read has been replayed)
    ingest_restarts: int = 0  # new ingest processes seen while replaying (their losses are in lost)
    stopped: bool = False  # stopped by SIGINT/SIGTERM before the end of the bag

    @property
    def lost(self) -> int:
        return max(self.published - self.acknowledged, 0)


class Replayer(Node):
    """Publishes the recording; counts ingest's acknowledgements (how many recording messages it
    has taken). A count that goes back is a new ingest process (a restart): what the old one took
    is kept (its last count), the new one's count is added to it, and the messages sent before the
    restart was seen no longer hold the flow control's credit (the dead process took those it had
    not acknowledged with it), so a replay goes on after an ingest restart; the result counts the
    restarts (what a dead process held is lost whatever its count said)."""

    def __init__(self, credit: int = 2000, namespace: str = "") -> None:
        super().__init__("shm_replay", namespace=namespace or None)
        self.credit = credit
        self.acknowledged = 0  # taken by ingest: the dead processes' last counts + the current one's
        self.published = 0
        self.offset = 0  # ingest's count when the replay began (it may have taken other bags before)
        self.taken_before = 0  # the last counts of ingest processes that died
        self.last_count = 0
        self.forgiven = 0  # messages published before the last restart was seen
        self.restarts = 0
        self.ack_seen = False
        self.create_subscription(UInt64, topics.INGEST_RECEIVED, self._on_ack, pipeline_qos())
        self.done_pub = self.create_publisher(String, topics.REPLAY_DONE, latched_qos())
        self.pubs: dict[str, Publisher] = {}

    def _on_ack(self, msg: UInt64) -> None:
        count = int(msg.data)
        if self.ack_seen and count < self.last_count:  # a new ingest process counts from 0
            self.restarts += 1
            self.taken_before += self.last_count
            self.forgiven = self.published
        self.ack_seen = True
        self.last_count = count
        self.acknowledged = self.taken_before + count

    @property
    def settled(self) -> int:
        """Acknowledged, or sent before an ingest restart was seen (credit for flow control)."""
        return max(self.acknowledged, self.offset + self.forgiven)

    def publisher(self, topic: str, msgtype: str) -> Publisher:
        pub = self.pubs.get(topic)
        if pub is None:
            cls = topics.message_class(msgtype)
            # Reliable, deep: matches best-effort (sensor-data) and reliable subscriptions.
            qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(self.credit, 10),
                             reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
            # relative: a replay in a namespace publishes the recording under it (/bridge_a/bridge/accel/s1)
            pub = self.create_publisher(cls, topic.lstrip("/"), qos)
            self.pubs[topic] = pub
        return pub


def _open_bag(path: str | Path) -> tuple[dict[str, str], Callable[[list[str]], Iterator[BagMessage]], str]:
    """Topics of the bag, a reader of its messages and, for a bag read another way than normal
    (no metadata, damaged files), why. The back end is chosen from what the bag is (see
    :func:`~shm_ros.io.sources.open_source`): a bag whose index or metadata is missing or damaged
    (a recorder that died) is read from its storage files directly, and its reader raises
    :class:`BagError` naming the file once everything readable has been replayed."""
    source = open_source(path)
    found = source.topics()
    if not found and source.note:
        raise BagError(f"{source.note}; no topic could be read")
    return found, source.messages, source.note


def replay_bag(path: str | Path, *, rate: float = 0.0, credit: int = 256,
               credit_bytes: int = 192 * 1024, wait_s: float = 10.0,
               drain_timeout_s: float = 300.0, stall_s: float = 30.0, recording_only: bool = True,
               progress: bool = False, clock_hz: float = 0.0, clock_readers: int = 0,
               namespace: str = "", stop: Callable[[], bool] | None = None) -> ReplayResult:
    """Publish the bag at ``path``; returns counts. Needs ``rclpy.init()`` to have been called.

    ``rate``: 1.0 = real time, N = N x real time, 0 = as fast as the graph acknowledges.
    ``recording_only``: replay only recording topics (docs/interfaces.md §1: accelerometers, blocks, temperature).
    ``stall_s``: with flow control, give up (``result.error``) when no acknowledgement arrives for
    this long (the ingest node is gone or stuck) instead of waiting forever.
    ``drain_timeout_s``: after the last message, how long to wait for the last acknowledgements;
    ingest holds them while its windows wait for slow readers (identify on a busy host), so this
    is generous.
    ``clock_readers``: with a clock, wait (up to ``wait_s``) until this many /clock readers (nodes on
    sim time) have matched; 0 = those the graph shows once they have stayed matched for
    ``CLOCK_SETTLE_S`` (a node discovered later than that takes the clock only from then on).
    ``namespace``: the graph's (``/bridge_a``); the recording's topics and the flow control go under it.
    ``stop``: asked before each message; True (a SIGINT or SIGTERM) ends the replay there, after
    which what was sent is drained and the graph is told the replay is done (``result.stopped``).
    """
    node = Replayer(credit, namespace)
    result = ReplayResult()
    try:
        # Publishers first (ingest discovers recording topics by polling the graph), then wait for
        # every recording topic to have a subscriber and for the ingest node's acknowledgements.
        bag_topic_types, reader, note = _open_bag(path)
        if note:
            node.get_logger().warning(note)
        for topic, msgtype in bag_topic_types.items():
            if recording_only and topic_kind(topic, msgtype) is None:
                result.skipped_topics[topic] = msgtype
                continue
            try:
                node.publisher(topic, msgtype)
            except (ImportError, AttributeError):
                result.skipped_topics[topic] = f"{msgtype} (type not available)"
        # /clock before the wait, and the wait includes its readers: a node whose clock subscription
        # matched only after the replay began would log the first windows at time 0
        clock = _Clock(node, clock_hz) if clock_hz > 0 else None
        deadline = time.monotonic() + wait_s
        settled: float | None = None  # with a clock: when its readers last looked complete
        while time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.05)
            # With flow control, wait for a first count from the ingest node: it may have taken
            # other bags before, and credits are counted from where its count stands now.
            if all(p.get_subscription_count() > 0 for p in node.pubs.values()) and (
                    rate > 0 or node.ack_seen) and (clock is None or clock.matched(node)):
                if clock is None or (clock_readers and clock.pub.get_subscription_count() >= clock_readers):
                    break
                if clock_readers:  # a known number of readers: wait for all of them, not for a settle
                    continue
                # this node may discover the graph's participants one at a time: a sim-time node
                # found a moment later (its /clock reader not yet counted) would miss the clock
                settled = time.monotonic() if settled is None else settled
                if time.monotonic() - settled >= CLOCK_SETTLE_S:
                    break
            else:
                settled = None
        if clock is not None and clock_readers and clock.pub.get_subscription_count() < clock_readers:
            node.get_logger().warning(f"{clock.pub.get_subscription_count()} of {clock_readers} /clock "
                                      f"readers after {wait_s:g} s: replaying anyway")
        flow = rate <= 0 and node.count_publishers(topics.INGEST_RECEIVED) > 0
        if rate <= 0 and not flow:
            node.get_logger().warning("no ingest acknowledgements: replaying without flow control")
        t0_wall = time.monotonic()
        t0_bag: int | None = None
        last_bag = 0
        start_ack = node.offset = node.acknowledged
        last_report = t0_wall
        sizes: deque[int] = deque()  # bytes of the messages not yet acknowledged
        in_flight_bytes = 0
        acked_upto = 0
        messages = reader(list(node.pubs))
        for k, m in enumerate(_until_error(messages, result)):
            if stop is not None and stop():
                result.stopped = True
                break
            t0_bag = m.receive_ns if t0_bag is None else t0_bag
            last_bag = m.receive_ns
            if clock is not None:
                clock.at(m.receive_ns)
            if rate > 0:
                due = t0_wall + (m.receive_ns - t0_bag) / 1e9 / rate
                while (delay := due - time.monotonic()) > 0:
                    rclpy.spin_once(node, timeout_sec=min(delay, 0.05))
            elif flow:
                progress_at, progress_ack = time.monotonic(), node.settled
                while True:
                    if node.settled != progress_ack:
                        progress_at, progress_ack = time.monotonic(), node.settled
                    elif time.monotonic() - progress_at > stall_s:
                        break
                    acked = node.settled - start_ack
                    while acked_upto < acked and sizes:
                        in_flight_bytes -= sizes.popleft()
                        acked_upto += 1
                    if result.published - acked < credit and (
                            in_flight_bytes + len(m.data) <= credit_bytes or not sizes):
                        break
                    rclpy.spin_once(node, timeout_sec=0.005)
                if time.monotonic() - progress_at > stall_s:
                    gone = node.count_publishers(topics.INGEST_RECEIVED) == 0
                    result.error = (f"{path}: no acknowledgement from the ingest node for {stall_s:g} s"
                                    f"{' (it left the graph)' if gone else ''}: replay stopped")
                    break
                sizes.append(len(m.data))
                in_flight_bytes += len(m.data)
            if not result.published:
                result.started_ns = time.time_ns()
            node.pubs[m.topic].publish(m.data)
            result.published += 1
            node.published = result.published
            if k % 200 == 0:
                rclpy.spin_once(node, timeout_sec=0)
            if progress and time.monotonic() - last_report > 2.0:
                last_report = time.monotonic()
                node.get_logger().info(f"replayed {k + 1} messages")
        # Drain: wait until the graph has taken everything that was sent.
        if flow or node.ack_seen:
            stalled = result.error.endswith("replay stopped")
            end = time.monotonic() + (0.0 if stalled else STOPPED_DRAIN_S if result.stopped else drain_timeout_s)
            quiet_since, seen = time.monotonic(), node.acknowledged
            while node.acknowledged - start_ack < result.published and time.monotonic() < end:
                rclpy.spin_once(node, timeout_sec=0.05)
                if node.acknowledged != seen:
                    quiet_since, seen = time.monotonic(), node.acknowledged
                if node.restarts and time.monotonic() - quiet_since > RESTART_QUIET_S:
                    break  # after an ingest restart, what is still missing went with the dead process
                if node.count_publishers(topics.INGEST_RECEIVED) == 0:  # ingest left: nothing more comes
                    result.error = result.error or (f"{path}: the ingest node left the graph before "
                                                    "acknowledging every message")
                    break
            # (after a restart the sum of the processes' counts can exceed what was sent: a count is
            # not an id; the restart itself is what the result reports)
            result.acknowledged = min(node.acknowledged - start_ack, result.published)
            result.ingest_restarts = node.restarts
        else:
            result.acknowledged = result.published
        result.wall_s = time.monotonic() - t0_wall
        if t0_bag is not None:
            result.bag_span_s = (last_bag - t0_bag) / 1e9
        node.done_pub.publish(String(data=str(path)))
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.05)
    finally:
        node.destroy_node()
    return result


RESTART_QUIET_S = 5.0  # s without new acknowledgements that end the drain after an ingest restart
STOPPED_DRAIN_S = 10.0  # s a stopped replay waits for the acknowledgements of what it sent
CLOCK_SETTLE_S = 1.0  # s the /clock readers must stay matched before the replay starts


class _Clock:
    """``/clock`` (rosgraph_msgs/Clock) with the recording's time, as ``ros2 bag play --clock``
    does, so that nodes started with ``use_sim_time:=true`` see recording time. Published before
    the first message and then whenever the recording has advanced by ``1 / hz`` seconds."""

    def __init__(self, node: Node, hz: float) -> None:
        from rosgraph_msgs.msg import Clock

        self.msg = Clock()
        self.step_ns = int(1e9 / hz)
        self.next_ns: int | None = None
        # reliable, last value only: matches the best-effort /clock subscription of every node
        self.pub = node.create_publisher(Clock, "/clock", QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.VOLATILE))

    def matched(self, node: Node) -> bool:
        """Every /clock reader the graph shows (at least one) has matched this publisher."""
        seen = node.count_subscribers("/clock")
        return seen > 0 and self.pub.get_subscription_count() >= seen

    def at(self, t_ns: int) -> None:
        if self.next_ns is not None and t_ns < self.next_ns:
            return
        self.msg.clock.sec, self.msg.clock.nanosec = split_ns(t_ns)
        self.pub.publish(self.msg)
        self.next_ns = t_ns + self.step_ns


def _until_error(messages: Iterator[BagMessage], result: ReplayResult) -> Iterator[BagMessage]:
    """The messages up to a read error, which is kept in ``result.error`` (the replay still drains
    and tells the graph it is done, so that what was read is windowed)."""
    try:
        yield from messages
    except BagError as exc:
        result.error = str(exc)
