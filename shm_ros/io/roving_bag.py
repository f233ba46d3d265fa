"""Roving recordings in rosbag2 bags (docs/interfaces.md section 8): accelerometers as
``sensor_msgs/msg/Imu`` on ``<prefix>/accel/<sensor id>`` (a roving sensor's ``header.frame_id`` is its
tf frame), the robot's transforms on ``/tf`` and ``/tf_static`` (``tf2_msgs/msg/TFMessage``, which the
rosbags typestore knows)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from shm_ros.core.roving.transforms import TransformBuffer
from shm_ros.core.structure import StructureSpec
from shm_ros.io.bags import IMU, BagWriter, read_messages, stamp_ns
from shm_ros.io.errors import BagError
from shm_ros.io.imu_cdr import decode_imu_batch

__all__ = ["TF", "write_roving_bag", "RovingBag", "read_roving_bag"]

TF = "tf2_msgs/msg/TFMessage"
PREFIX = "/shm"


def _tf_message(w: BagWriter, samples) -> object:
    t = w._types
    out = []
    for s in samples:
        sec, nsec = divmod(int(s.stamp_ns), 1_000_000_000)
        out.append(t["geometry_msgs/msg/TransformStamped"](
            header=t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
                                            frame_id=s.parent),
            child_frame_id=s.child,
            transform=t["geometry_msgs/msg/Transform"](
                translation=t["geometry_msgs/msg/Vector3"](x=s.translation[0], y=s.translation[1], z=s.translation[2]),
                rotation=t["geometry_msgs/msg/Quaternion"](x=s.rotation[0], y=s.rotation[1], z=s.rotation[2],
                                                           w=s.rotation[3]))))
    return t[TF](transforms=out)


def write_roving_bag(rec, path: str | Path, prefix: str = PREFIX) -> Path:
    """Write a :class:`~shm_ros.core.simulate.roving.RovingRecording` (references, roving sensors, tf)."""
    path = Path(path)
    frames = {s.id: s.frame for s in rec.spec.roving}
    src = {s.id: s.source for s in rec.spec.sensors}  # each reference on the axis the reader takes it from

    def on_axis(rid: str, x: np.ndarray) -> np.ndarray:
        out = np.zeros((x.size, 3))
        out[:, {"x": 0, "y": 1, "z": 2}[src[rid].axis]] = x * src[rid].sign
        return out

    with BagWriter(path) as w:
        w.imu_streams({f"{prefix}/accel/{rid}": (rec.times_ns, on_axis(rid, x)) for rid, x in rec.references.items()})
        for sid, xyz in rec.roving.items():
            w._frame_id = frames[sid]
            w.imu_series(f"{prefix}/accel/{sid}", rec.times_ns, xyz)
        w._frame_id = ""
        if rec.tf_static:
            w.write("/tf_static", TF, 0, _tf_message(w, rec.tf_static))
        by_stamp: dict[int, list] = {}
        for s in rec.tf:
            by_stamp.setdefault(s.stamp_ns, []).append(s)
        for t_ns in sorted(by_stamp):
            w.write("/tf", TF, t_ns, _tf_message(w, by_stamp[t_ns]))
    return path


@dataclass
class RovingBag:
    times_ns: np.ndarray
    fs: float
    references: dict[str, np.ndarray]
    roving: dict[str, np.ndarray]
    buffer: TransformBuffer


def read_roving_bag(path: str | Path, spec: StructureSpec) -> RovingBag:
    """The structure's fixed sensors (their ``source.axis``) and roving sensors (3 axes) from their Imu
    topics, on the references' sample times, and every transform of ``/tf`` and ``/tf_static``."""
    path = Path(path)
    imu: dict[str, list[bytes]] = {}
    buf = TransformBuffer(cache_s=None)
    for m in read_messages(path):
        if m.msgtype == IMU:
            imu.setdefault(m.topic.rsplit("/", 1)[-1], []).append(m.data)
        elif m.msgtype == TF and m.topic in ("/tf", "/tf_static"):
            for tr in m.decode().transforms:
                v, q = tr.transform.translation, tr.transform.rotation
                buf.set_transform(tr.header.frame_id, tr.child_frame_id, stamp_ns(tr.header.stamp),
                                  (v.x, v.y, v.z), (q.x, q.y, q.z, q.w), static=m.topic == "/tf_static")
    decoded = {k: decode_imu_batch(v) for k, v in imu.items()}
    missing = [s.source.topic or s.id for s in spec.sensors if (s.source.topic or s.id) not in decoded] + \
        [r.source.topic or r.id for r in spec.roving if (r.source.topic or r.id) not in decoded]
    if missing:
        raise BagError(f"{path}: no Imu topic .../accel/<id> for sensor(s) {missing}")
    first = spec.sensors[0]
    times = decoded[first.source.topic or first.id][0]
    axis = {"x": 0, "y": 1, "z": 2}
    refs, rov = {}, {}
    for s in spec.sensors:
        t, xyz = decoded[s.source.topic or s.id]
        if t.size != times.size or np.any(t != times):
            raise BagError(f"{path}: sensor {s.id!r}: its Imu stamps differ from {first.id!r}'s (one clock expected)")
        refs[s.id] = xyz[:, axis[s.source.axis]] * s.source.sign
    for r in spec.roving:
        t, xyz = decoded[r.source.topic or r.id]
        if t.size != times.size:
            raise BagError(f"{path}: roving sensor {r.id!r}: {t.size} samples, the references {times.size}")
        rov[r.id] = xyz
    fs = 1e9 / float(np.median(np.diff(times)))
    return RovingBag(times, fs, refs, rov, buf)
