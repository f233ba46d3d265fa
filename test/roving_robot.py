"""A test robot for the live roving graph: it publishes what its sensors and localisation record
(Imu on ``shm/accel/<id>``, ``/tf``, ``/tf_static``) from a simulated recording, drives the roving
node's ``RecordPoint`` action, and replays bags; everything over a real DDS (rmw_fastrtps)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def start_node(structure: Path, **params) -> subprocess.Popen:
    args = [sys.executable, "-m", "shm_ros.ros.roving_node", "--ros-args", "-p", f"structure:={structure}",
            "-p", "reliable_input:=true"] + [a for k, v in params.items() for a in ("-p", f"{k}:={v}")]
    return subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=dict(os.environ, PYTHONUNBUFFERED="1"))


def stop_node(proc: subprocess.Popen) -> str:
    proc.terminate()
    try:
        out, _ = proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    return out


@dataclass
class Goal:
    point: str
    feedback: list = field(default_factory=list)  # (status, recorded_s, shape_std list)
    result: object | None = None


class Robot:
    """Publishers, the action client and the node's acknowledgements (see module doc)."""

    def __init__(self, spec) -> None:
        import rclpy
        from rclpy.action import ActionClient
        from rclpy.node import Node
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import Imu
        from shm_interfaces.action import RecordPoint
        from std_msgs.msg import String, UInt64
        from tf2_msgs.msg import TFMessage

        self.rclpy, self.spec = rclpy, spec
        self.node = Node("test_robot")
        rel = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=20000, reliability=ReliabilityPolicy.RELIABLE)
        latched = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.imu = {s.id: self.node.create_publisher(Imu, f"shm/accel/{s.id}", rel)
                    for s in list(spec.sensors) + list(spec.roving)}
        self.tf = self.node.create_publisher(TFMessage, "/tf", rel)
        self.tf_static = self.node.create_publisher(TFMessage, "/tf_static", latched)
        self.acked = 0
        self.modes: dict | None = None
        self.node.create_subscription(UInt64, "shm/roving/received", self._on_ack, latched)
        self.node.create_subscription(String, "shm/roving/modes", self._on_modes, latched)
        self.client = ActionClient(self.node, RecordPoint, "shm/roving/record_point")
        self.RecordPoint, self.Imu, self.TFMessage = RecordPoint, Imu, TFMessage
        self.published = 0

    def _on_ack(self, msg) -> None:
        self.acked = msg.data

    def _on_modes(self, msg) -> None:
        self.modes = json.loads(msg.data)

    def spin_until(self, cond, timeout_s: float, what: str) -> None:
        end = time.monotonic() + timeout_s
        while not cond():
            if time.monotonic() > end:
                raise TimeoutError(f"test robot: waited {timeout_s} s for {what}")
            self.rclpy.spin_once(self.node, timeout_sec=0.02)

    def wait_for_node(self) -> None:
        self.spin_until(lambda: self.client.server_is_ready() and all(
            p.get_subscription_count() > 0 for p in [*self.imu.values(), self.tf]), 60.0, "the roving node")

    def close(self) -> None:
        self.client.destroy()
        self.node.destroy_node()

    # -- recording ---------------------------------------------------------------------------------
    def load(self, rec) -> None:
        self.rec, self.i, self.k_tf = rec, 0, 0
        self.tfs = sorted(rec.tf, key=lambda s: s.stamp_ns)

    def _tf_msg(self, samples):
        from geometry_msgs.msg import TransformStamped
        out = []
        for s in samples:
            t = TransformStamped()
            t.header.stamp.sec, t.header.stamp.nanosec = divmod(int(s.stamp_ns), 1_000_000_000)
            t.header.frame_id, t.child_frame_id = s.parent, s.child
            t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = s.translation
            q = t.transform.rotation
            q.x, q.y, q.z, q.w = s.rotation
            out.append(t)
        return self.TFMessage(transforms=out)

    def publish_to(self, i_end: int) -> None:
        """Publish samples up to index ``i_end`` (and /tf 0.2 s ahead), then wait until the node took them."""
        rec, frames = self.rec, {s.id: s.frame for s in self.spec.roving}
        horizon = rec.times_ns[min(i_end, rec.times_ns.size) - 1] + 200_000_000
        batch = []
        while self.k_tf < len(self.tfs) and self.tfs[self.k_tf].stamp_ns <= horizon:
            batch.append(self.tfs[self.k_tf])
            self.k_tf += 1
        if batch:
            self.tf.publish(self._tf_msg(batch))
        for i in range(self.i, i_end):
            sec, nsec = divmod(int(rec.times_ns[i]), 1_000_000_000)
            for sid, x in list(rec.references.items()) + list(rec.roving.items()):
                m = self.Imu()
                m.header.stamp.sec, m.header.stamp.nanosec = sec, nsec
                m.header.frame_id = frames.get(sid, "")
                v = np.atleast_1d(x[i])
                if v.size == 3:
                    m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z = map(float, v)
                else:
                    m.linear_acceleration.z = float(v[0])
                self.imu[sid].publish(m)
                self.published += 1
        self.i = max(self.i, i_end)
        self.spin_until(lambda: self.acked >= self.published, 120.0, f"{self.published} samples taken")

    def goal_accepted(self, point: str) -> bool:
        """Send a goal for ``point`` and say whether the node accepted it (cancelled at once if so)."""
        fut = self.client.send_goal_async(self.RecordPoint.Goal(point_id=point))
        self.spin_until(fut.done, 30.0, "the goal's answer")
        handle = fut.result()
        if handle.accepted:
            handle.cancel_goal_async()
        return bool(handle.accepted)

    def record_at(self, point: str, i0: int, i1: int, chunk_s: float = 5.0) -> Goal:
        """Stand at ``point`` over samples [i0, i1): send the goal, publish ``chunk_s`` at a time and
        wait for the estimate of each; leave (cancel) at the end of the dwell or once enough."""
        from builtin_interfaces.msg import Time
        self.publish_to(i0)
        goal = Goal(point)
        sec, nsec = divmod(int(self.rec.times_ns[i0]), 1_000_000_000)
        fut = self.client.send_goal_async(self.RecordPoint.Goal(point_id=point, since=Time(sec=sec, nanosec=nsec)),
                                          feedback_callback=lambda f: goal.feedback.append(
                                              (f.feedback.status, f.feedback.recorded_s, list(f.feedback.shape_std))))
        self.spin_until(fut.done, 30.0, "the goal's acceptance")
        handle = fut.result()
        assert handle.accepted
        res = handle.get_result_async()
        step = max(1, int(round(chunk_s * self.rec_fs)))
        for k, i in enumerate(range(i0 + step, i1 + 1, step)):
            self.publish_to(i)
            self.spin_until(lambda k=k: res.done() or len(goal.feedback) > k, 120.0, f"estimate {k + 1} at {point}")
            if res.done():
                break
        if not res.done():
            handle.cancel_goal_async()
        self.spin_until(res.done, 60.0, "the goal's result")
        goal.result = res.result().result
        return goal

    @property
    def rec_fs(self) -> float:
        return 1e9 / float(np.median(np.diff(self.rec.times_ns[:100])))

    def replay_bag(self, path: Path) -> None:
        """Every message of the bag, as stored (CDR bytes), with the node's acknowledgements as flow control."""
        from shm_ros.io.bags import IMU, read_messages
        pubs = {**{f"/shm/accel/{k}": p for k, p in self.imu.items()}, "/tf": self.tf, "/tf_static": self.tf_static}
        n = 0
        for m in read_messages(path):
            if m.topic in pubs:
                pubs[m.topic].publish(m.data)
                if m.msgtype == IMU:
                    self.published += 1
                    n += 1
                    if n % 2000 == 0:
                        self.spin_until(lambda: self.acked >= self.published, 120.0, "the bag's samples taken")
        self.spin_until(lambda: self.acked >= self.published, 120.0, "the bag's samples taken")
