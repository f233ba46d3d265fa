"""roving: a robot's roving sensors and tf in, advice to the robot and global mode shapes out.

Subscribes to ``shm/accel/<id>`` (sensor_msgs/Imu) of every fixed and roving sensor of the structure
file, and to ``/tf`` and ``/tf_static`` (tf2_msgs/TFMessage) as they come. Serves the action
``shm/roving/record_point`` (shm_interfaces/action/RecordPoint): the robot sends the point where it
stands; after every ``advise_every_s`` of recorded data the feedback says ``continue`` or ``enough``
(with why not); once enough the goal succeeds with the point that reduces the global shapes'
uncertainty most, also as a ``geometry_msgs/PoseStamped`` in the structure's frame. When the input
has been idle for ``idle_flush_s`` the global modes of everything received (the offline pipeline)
go out on ``shm/roving/modes`` (std_msgs/String, JSON: ``setups`` and ``global_modes`` of
docs/interfaces.md section 8, latched). All science is in :class:`shm_ros.core.roving.live.LiveRoving`.
"""

from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass, fields
from typing import Any

from geometry_msgs.msg import PoseStamped
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String, UInt64

from shm_ros.core.config import option
from shm_ros.core.roving.live import AdviceConfig, LiveRoving, PointAdvice
from shm_ros.core.roving.pipeline import RovingConfig
from shm_ros.errors import ShmError
from shm_ros.io.imu_cdr import decode_imu_batch
from shm_ros.ros.managed import ManagedNode
from shm_ros.ros.node_main import spin
from shm_ros.ros.params import ParameterError, load_config
from shm_ros.ros.qos import latched_qos, recording_qos

ACTION = "shm/roving/record_point"
MODES = "shm/roving/modes"
RECEIVED = "shm/roving/received"
TF_DEPTH = 1000


@dataclass
class RovingNodeConfig:
    structure: str | None = option(None, "path of the structure YAML with frame, roving sensors and "
                                   "measurement points (required)")
    shape_std_max: float = option(0.05, "enough: every mode of interest's shape std at the point below this")
    frequency_tol: float = option(0.005, "enough: frequencies stable within this fraction over n_stable estimates")
    n_stable: int = option(3, "enough: estimates the frequency must be stable over")
    n_modes: int = option(3, "modes of interest: the lowest of the nominal model")
    advise_every_s: float = option(5.0, "recorded seconds between two estimates of the current setup")
    merge: str = option("post", "how the global modes merge the setups: post or pre")
    idle_flush_s: float = option(3.0, "wall-clock seconds without input after which the global modes go out")
    reliable_input: bool = option(False, "subscribe to the accelerometers reliable (default: best effort)")


class RovingNode(ManagedNode):
    """Parameters: the options of :class:`RovingNodeConfig`."""

    kind = "roving"

    def setup(self) -> None:
        from shm_interfaces.action import RecordPoint
        from tf2_msgs.msg import TFMessage

        from shm_ros.io.structure import load_structure

        s = load_config(self, RovingNodeConfig)
        if not s.structure:
            raise ParameterError(f"{self.get_name()}: parameter 'structure' is required")
        try:
            self.spec = load_structure(s.structure)
            advice = AdviceConfig(**{f.name: getattr(s, f.name) for f in fields(AdviceConfig)
                                     if hasattr(s, f.name)})
            self.core = LiveRoving(self.spec, RovingConfig(merge=s.merge), advice)
        except ShmError as exc:
            raise ParameterError(f"{self.get_name()}: parameter 'structure': {exc}") from exc
        self.settings = s
        self.lock = threading.Lock()
        self.raw: dict[str, list[bytes]] = {k: [] for k in self.core.streams}
        self.received = self.fed = self.flushed = 0
        self.last_input = time.monotonic()
        data = MutuallyExclusiveCallbackGroup()
        for sid in self.core.streams:
            self.create_subscription(self._imu_class(), f"shm/accel/{sid}", lambda m, k=sid: self._on_imu(k, m),
                                     recording_qos(reliable=s.reliable_input), raw=True, callback_group=data)
        self.create_subscription(TFMessage, "/tf", self._on_tf, QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=TF_DEPTH, reliability=ReliabilityPolicy.RELIABLE),
            callback_group=data)
        self.create_subscription(TFMessage, "/tf_static", lambda m: self._on_tf(m, True), QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=TF_DEPTH, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL), callback_group=data)
        self.received_pub = self.create_publisher(UInt64, RECEIVED, latched_qos())
        self.modes_pub = self.create_publisher(String, MODES, latched_qos())
        self.create_timer(0.05, self._feed, callback_group=data)
        self.create_timer(0.5, self._maybe_flush, callback_group=MutuallyExclusiveCallbackGroup())
        self.action = ActionServer(self, RecordPoint, ACTION, self._execute, goal_callback=self._on_goal,
                                   cancel_callback=lambda _: CancelResponse.ACCEPT,
                                   callback_group=ReentrantCallbackGroup())
        self.diag.summarize(lambda: ("ok", f"{self.received} accelerometer messages, "
                                     f"{len(self.core.visited)} setups finished", {"received": self.received}))

    @staticmethod
    def _imu_class() -> Any:
        from sensor_msgs.msg import Imu
        return Imu

    def teardown(self) -> None:
        self.action.destroy()

    # -- input ------------------------------------------------------------------------------------
    def _on_imu(self, sensor: str, data: bytes) -> None:
        self.raw[sensor].append(data)
        self.received += 1
        self.last_input = time.monotonic()

    def _on_tf(self, msg: Any, static: bool = False) -> None:
        with self.lock:
            for tr in msg.transforms:
                v, q = tr.transform.translation, tr.transform.rotation
                stamp = tr.header.stamp.sec * 1_000_000_000 + tr.header.stamp.nanosec
                try:
                    self.core.add_transform(tr.header.frame_id, tr.child_frame_id, stamp, (v.x, v.y, v.z),
                                            (q.x, q.y, q.z, q.w), static)
                except (ShmError, ValueError) as exc:  # one bad transform never takes the node down
                    self.diag.report("warn", f"transform refused: {exc}", "/tf_static" if static else "/tf")
        self.last_input = time.monotonic()

    def _feed(self) -> None:
        taken = 0
        with self.lock:
            for sid, datas in self.raw.items():
                batch, self.raw[sid] = datas, []
                if not batch:
                    continue
                try:
                    t, xyz = decode_imu_batch(batch)
                except ValueError as exc:
                    self.diag.report("error", f"Imu messages refused: {exc}", f"shm/accel/{sid}")
                    continue
                axis = "xyz".index(self._axis(sid))
                self.core.add_samples(sid, t, xyz if self._is_roving(sid) else xyz[:, axis] * self._sign(sid))
                taken += len(batch)
        if taken:
            self.fed += taken
            self.received_pub.publish(UInt64(data=self.fed))

    def _is_roving(self, sid: str) -> bool:
        return any(r.id == sid for r in self.spec.roving)

    def _axis(self, sid: str) -> str:
        return next(s.source.axis for s in self.spec.sensors if s.id == sid) if not self._is_roving(sid) else "z"

    def _sign(self, sid: str) -> float:
        return float(next(s.source.sign for s in self.spec.sensors if s.id == sid))

    def _maybe_flush(self) -> None:
        """Idle input and new samples: the global modes of everything received go out."""
        if self.fed == self.flushed or time.monotonic() - self.last_input < self.settings.idle_flush_s:
            return
        self.flushed = self.fed
        try:
            with self.lock:
                result, samples = self.core.result(), self.core.samples
        except ShmError as exc:
            self.diag.report("warn", f"no global modes yet: {exc}", MODES)
            return
        payload = result.to_dict()
        payload["roving"]["samples"] = samples  # what these modes are of
        self.modes_pub.publish(String(data=json.dumps(payload)))
        self.get_logger().info(f"global modes of {len(result.cut.setups)} setups at "
                               + ", ".join(f"{g.frequency_hz:.3f}" for g in result.global_modes) + " Hz")

    # -- the robot --------------------------------------------------------------------------------
    def _on_goal(self, goal: Any) -> GoalResponse:
        if goal.point_id not in {p.id for p in self.spec.measurement_points}:
            self.get_logger().warning(f"{ACTION}: unknown point {goal.point_id!r}: goal rejected")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _execute(self, handle: Any) -> Any:
        from shm_interfaces.action import RecordPoint

        since = handle.request.since.sec * 1_000_000_000 + handle.request.since.nanosec
        with self.lock:
            self.core.start(handle.request.point_id, since)
        step = 0
        advice: PointAdvice | None = None
        while True:
            if handle.is_cancel_requested:
                handle.canceled()
                return self._result(RecordPoint.Result(), advice, handle.request.point_id)
            try:
                with self.lock:
                    ready = self.core.recorded_s() >= self.settings.advise_every_s * (step + 1) - 1e-9
                    if ready:
                        step += 1
                        advice = self.core.advise()
            except Exception as exc:  # noqa: BLE001 - one bad estimate ends this goal, never the node
                self.diag.report("error", f"no estimate at {handle.request.point_id}: {exc}", ACTION)
                handle.abort()
                out = self._result(RecordPoint.Result(), advice, handle.request.point_id)
                out.reasons = list(out.reasons) + [f"estimate failed: {exc}"]
                return out
            if not ready or advice is None:
                time.sleep(0.02)
                continue
            handle.publish_feedback(RecordPoint.Feedback(
                status=advice.status, point_id=advice.point_id, recorded_s=advice.recorded_s,
                reasons=advice.reasons, frequencies_hz=advice.frequencies_hz, shape_std=advice.shape_std))
            if advice.enough:
                handle.succeed()
                return self._result(RecordPoint.Result(), advice, handle.request.point_id)

    def _result(self, out: Any, advice: PointAdvice | None, point: str) -> Any:
        out.point_id = point
        if advice is None:
            out.reasons = ["no estimate yet"]
            return out
        out.enough, out.reasons = advice.enough, advice.reasons
        out.frequencies_hz, out.shape_std = advice.frequencies_hz, advice.shape_std
        out.next_point_id, out.expected_reduction = advice.next_point_id, advice.expected_reduction
        pose = PoseStamped()
        pose.header.frame_id = self.spec.frame
        pose.header.stamp = self.get_clock().now().to_msg()
        if advice.next_position is not None:
            pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = advice.next_position
            pose.pose.orientation.w = 1.0
        out.next_pose = pose
        return out


def make_node(name: str, parameters: dict[str, Any], namespace: str = "") -> RovingNode:
    return RovingNode(name, parameters, namespace)


def _executor() -> Any:
    from rclpy.executors import MultiThreadedExecutor
    return MultiThreadedExecutor(num_threads=3)


def main(args: list[str] | None = None) -> int:
    return spin(lambda: RovingNode(), args, executor_factory=_executor)


if __name__ == "__main__":
    raise SystemExit(main())
