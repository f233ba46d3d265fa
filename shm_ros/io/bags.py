"""rosbag2 bags (MCAP or sqlite3) in and out, without a ROS installation, through ``rosbags``.

Topics follow docs/interfaces.md §1: ``<prefix>/accel/<sensor_id>`` (``sensor_msgs/msg/Imu``, one
sample per message), ``<prefix>/accel_block`` (``shm_interfaces/msg/AccelBlock``) and
``<prefix>/temperature/<sensor_id>`` (``sensor_msgs/msg/Temperature``).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.core.timeutil import join_ns, split_ns
from shm_ros.io.errors import BagError
from shm_ros.io.faults import fault_point
from shm_ros.io.sources.base import BagMessage
from shm_ros.io.typestore import typestore

__all__ = ["ACCEL_BLOCK", "IMU", "TEMPERATURE", "BagError", "BagMessage", "BagWriter", "bag_topics",
           "read_messages", "split_ns", "stamp_ns", "topic_kind"]

IMU = "sensor_msgs/msg/Imu"
TEMPERATURE = "sensor_msgs/msg/Temperature"
ACCEL_BLOCK = "shm_interfaces/msg/AccelBlock"


def stamp_ns(stamp: Any) -> int:
    return join_ns(stamp.sec, stamp.nanosec)


class BagWriter:
    """Writes recording topics (docs/interfaces.md §1; and any registered type) into a new rosbag2 bag.

    ``storage`` is ``"mcap"`` (default, what ``ros2 bag record`` writes) or ``"sqlite3"``;
    ``compress=True`` zstd-compresses MCAP chunks (``--storage-preset-profile zstd_fast``).
    """

    def __init__(self, path: str | Path, *, storage: str = "mcap", compress: bool = False,
                 frame_id: str = "") -> None:
        from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

        self.path = Path(path)
        plugin = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}.get(storage)
        if plugin is None:
            raise BagError(f"{self.path}: unknown storage {storage!r} (mcap or sqlite3)")
        self._writer = Writer(self.path, version=9, storage_plugin=plugin)
        if compress:
            mode = CompressionMode.STORAGE if storage == "mcap" else CompressionMode.MESSAGE
            self._writer.set_compression(mode, CompressionFormat.ZSTD)
        self._ts = typestore()
        self._connections: dict[str, Any] = {}
        self._frame_id = frame_id
        self._types = self._ts.types

    def __enter__(self) -> BagWriter:
        self._writer.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self._writer.close()

    def connection(self, topic: str, msgtype: str) -> Any:
        conn = self._connections.get(topic)
        if conn is None:
            conn = self._writer.add_connection(
                topic, msgtype, typestore=self._ts, rihs01=self._ts.hash_rihs01(msgtype)
            )
            self._connections[topic] = conn
        return conn

    def write(self, topic: str, msgtype: str, t_ns: int, msg: Any) -> None:
        """Write any message object of the typestore."""
        self._writer.write(self.connection(topic, msgtype), int(t_ns), self._ts.serialize_cdr(msg, msgtype))

    def write_cdr(self, topic: str, msgtype: str, t_ns: int, data: bytes) -> None:
        self._writer.write(self.connection(topic, msgtype), int(t_ns), data)

    def flush(self) -> None:
        """Put what was written so far on disk, complete (MCAP: the pending chunk closed and
        written; sqlite3: committed), so that a process killed afterwards loses none of it."""
        storage: Any = self._writer.storage
        if hasattr(storage, "close_chunk"):
            if storage.chunk.msgs:
                storage.close_chunk()
            # a test hook: killed here, a large record is partly on disk (the file's buffer is 8 KiB)
            fault_point("bag", "write")
            storage.bio.flush()  # to the kernel: a killed process loses nothing (a power cut may)
        elif hasattr(storage, "conn"):
            storage.conn.commit()

    def header(self, t_ns: int) -> Any:
        sec, nsec = split_ns(t_ns)
        return self._types["std_msgs/msg/Header"](
            stamp=self._types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
            frame_id=self._frame_id,
        )

    def accel_block(self, topic: str, t_ns: int, sample_rate_hz: float,
                    channel_names: Sequence[str], samples: np.ndarray, units: str = "m/s^2") -> None:
        """One ``AccelBlock``: ``samples`` is (n_samples, n_channels); ``t_ns`` the first sample."""
        samples = np.ascontiguousarray(samples, dtype=np.float64)
        if samples.ndim != 2 or samples.shape[1] != len(channel_names):
            raise BagError(f"{self.path}: {topic}: samples must be (n, {len(channel_names)})")
        msg = self._types[ACCEL_BLOCK](
            header=self.header(t_ns), sample_rate_hz=float(sample_rate_hz),
            channel_names=list(channel_names), samples=samples.reshape(-1), units=units,
        )
        self.write(topic, ACCEL_BLOCK, t_ns, msg)

    def imu_series(self, topic: str, stamps_ns: np.ndarray, accel_xyz: np.ndarray,
                   receive_ns: np.ndarray | None = None) -> None:
        """One ``Imu`` message per sample; ``accel_xyz`` is (n, 3) in m/s^2."""
        Imu = self._types[IMU]
        V3 = self._types["geometry_msgs/msg/Vector3"]
        Q = self._types["geometry_msgs/msg/Quaternion"]
        zeros9 = np.zeros(9)
        cov_unknown = np.zeros(9)
        cov_unknown[0] = -1.0  # REP-145: orientation not provided
        receive_ns = stamps_ns if receive_ns is None else receive_ns
        conn = self.connection(topic, IMU)
        ser = self._ts.serialize_cdr
        for t, rt, (ax, ay, az) in zip(stamps_ns.tolist(), receive_ns.tolist(), accel_xyz.tolist(), strict=True):
            msg = Imu(
                header=self.header(t), orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=cov_unknown, angular_velocity=V3(x=0.0, y=0.0, z=0.0),
                angular_velocity_covariance=zeros9, linear_acceleration=V3(x=ax, y=ay, z=az),
                linear_acceleration_covariance=zeros9,
            )
            self._writer.write(conn, int(rt), ser(msg, IMU))

    def imu_streams(self, streams: dict[str, tuple[np.ndarray, np.ndarray]]) -> None:
        """Several Imu topics written the way a recorder receives them: interleaved in stamp order.

        ``streams`` maps topic -> (stamps_ns (n,), accel_xyz (n, 3)).
        """
        topics_, stamps, rows = [], [], []
        for k, (topic, (t, _xyz)) in enumerate(streams.items()):
            topics_.append(topic)
            stamps.append(np.asarray(t, dtype=np.int64))
            rows.append(np.full(len(t), k))
        t_all = np.concatenate(stamps)
        which = np.concatenate(rows)
        pos = np.concatenate([np.arange(len(t)) for t in stamps])
        order = np.argsort(t_all, kind="stable")
        for topic in topics_:
            self.connection(topic, IMU)
        # One message at a time in global stamp order (runs of one topic are written together).
        breaks = np.flatnonzero(np.diff(which[order])) + 1
        for run in np.split(order, breaks):
            k = int(which[run[0]])
            idx = pos[run]
            t, xyz = streams[topics_[k]]
            self.imu_series(topics_[k], np.asarray(t)[idx], np.asarray(xyz)[idx])

    def temperature(self, topic: str, t_ns: int, value_c: float, variance: float = 0.0) -> None:
        msg = self._types[TEMPERATURE](header=self.header(t_ns), temperature=float(value_c),
                                      variance=float(variance))
        self.write(topic, TEMPERATURE, t_ns, msg)


def topic_kind(topic: str, msgtype: str) -> tuple[str, str] | None:
    """``("imu", sensor_id)``, ``("block", "")``, ``("temperature", sensor_id)`` or None (ignored)."""
    parts = topic.rstrip("/").split("/")
    if msgtype == IMU and len(parts) >= 2 and parts[-2] == "accel":
        return "imu", parts[-1]
    if msgtype == ACCEL_BLOCK and parts[-1] == "accel_block":
        return "block", ""
    if msgtype == TEMPERATURE and len(parts) >= 2 and parts[-2] == "temperature":
        return "temperature", parts[-1]
    return None


def read_messages(path: str | Path, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
    """Raw messages of a bag in receive-time order, as ``rosbags`` reads them (CDR bytes;
    ``decode()`` when needed).

    Unknown message types are skipped; a truncated or unreadable bag raises :class:`BagError`
    naming the bag, after every message read so far has been yielded. (To read any bag,
    damaged ones included, the fastest way, see :func:`shm_ros.io.sources.open_source`.)
    """
    from shm_ros.io.sources.rosbags_reader import RosbagsSource

    path = Path(path)
    if not path.exists():
        raise BagError(f"{path}: no such bag")
    return RosbagsSource(path).messages(None if topics is None else set(topics))


def bag_topics(path: str | Path) -> dict[str, str]:
    """``{topic: msgtype}`` of a bag, as ``rosbags`` reads it."""
    from shm_ros.io.sources.rosbags_reader import RosbagsSource

    return RosbagsSource(Path(path)).topics()
