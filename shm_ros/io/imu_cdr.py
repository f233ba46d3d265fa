"""``sensor_msgs/msg/Imu`` messages decoded in batches straight from their CDR bytes.

Deserialising message by message (rosbags) costs ~6 us each, more than everything else of the
ingest path together, and per-sample Imu recordings hold hundreds of samples per second per
sensor. One numpy pass reads the stamp and the linear acceleration of a whole batch, in either
CDR byte order and with any ``frame_id`` length; the messages whose size does not fit that layout
(another encapsulation, extra bytes) go through the rosbags deserialiser one by one, which
validates them. Every reader of Imu bytes (each bag source, the live ingest node) uses this.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

IMU = "sensor_msgs/msg/Imu"

#: Bytes after the 8-byte aligned start of ``orientation``: orientation (32) + covariance (72) +
#: angular velocity (24) + covariance (72) + linear acceleration (24) + covariance (72).
_BODY = 296
#: Offset of ``linear_acceleration`` from the start of ``orientation``.
_ACCEL = 200
#: Smallest message of the layout: encapsulation (4) + stamp (8) + frame_id length (4) + its NUL,
#: aligned to 8 from the start of the body (offset 4).
MIN_LEN = 20 + _BODY


@dataclass(frozen=True)
class ImuSamples:
    """The decoded messages, in input order; ``failures`` are ``(index, why)`` of the messages
    that could not be decoded (left out of ``stamps_ns`` and ``xyz``)."""

    stamps_ns: np.ndarray  # (n,) int64
    xyz: np.ndarray  # (n, 3) float64, m/s^2
    failures: list[tuple[int, str]]


def decode_imu_batch(datas: list[bytes]) -> tuple[np.ndarray, np.ndarray]:
    """``(stamps_ns (n,), linear_acceleration (n, 3))`` of CDR-serialised Imu messages.

    Raises ``ValueError`` naming the first message that cannot be decoded.
    """
    lengths = np.fromiter((len(d) for d in datas), np.int64, len(datas))
    starts = np.concatenate(([0], np.cumsum(lengths)[:-1])).astype(np.int64)
    buf = np.frombuffer(b"".join(datas), dtype=np.uint8)
    out = decode_imu_views(buf, starts, lengths)
    if out.failures:
        i, why = out.failures[0]
        raise ValueError(f"message {i}: {why}")
    return out.stamps_ns, out.xyz


def decode_imu_views(buf: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> ImuSamples:
    """The Imu messages at ``buf[starts[i]:starts[i] + lengths[i]]`` (``buf`` is uint8)."""
    n = starts.size
    stamps = np.zeros(n, np.int64)
    xyz = np.zeros((n, 3), np.float64)
    fast = _decode_fast(buf, starts, lengths, stamps, xyz)
    failures: list[tuple[int, str]] = []
    for i in np.flatnonzero(~fast).tolist():
        try:
            stamps[i], xyz[i] = _decode_one(bytes(buf[starts[i]:starts[i] + lengths[i]]))
        except ValueError as exc:
            failures.append((i, str(exc)))
    if failures:
        keep = np.ones(n, bool)
        keep[[i for i, _ in failures]] = False
        stamps, xyz = stamps[keep], xyz[keep]
    return ImuSamples(stamps, xyz, failures)


def _gather(buf: np.ndarray, starts: np.ndarray, width: int) -> np.ndarray:
    """``(len(starts), width)`` bytes of ``buf`` starting at each of ``starts``."""
    return np.ascontiguousarray(buf[starts[:, None] + np.arange(width)])


def _decode_fast(buf: np.ndarray, starts: np.ndarray, lengths: np.ndarray,
                 stamps: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """Fill ``stamps``/``xyz`` where the plain CDR layout applies; returns where it did."""
    fast = lengths >= MIN_LEN
    r = np.flatnonzero(fast)
    if not r.size:
        return fast
    head = _gather(buf, starts[r], 16)
    little = (head[:, 0] == 0) & (head[:, 1] == 1)  # encapsulation CDR_LE
    big = (head[:, 0] == 0) & (head[:, 1] == 0)  # CDR_BE
    raw = head[:, 4:16].copy()
    words = np.where(big[:, None], raw.view(">u4"), raw.view("<u4")).astype(np.int64)  # sec, nanosec, len
    pos = 16 + words[:, 2]  # end of frame_id (its length counts the NUL)
    orient = 4 + ((pos - 4 + 7) // 8) * 8  # 8-byte alignment is counted from the body (offset 4)
    good = (little | big) & (words[:, 2] >= 1) & (orient + _BODY == lengths[r])
    nul = np.zeros_like(good)
    nul[good] = buf[starts[r[good]] + pos[good] - 1] == 0  # a CDR string ends with its NUL
    good &= nul
    fast[r[~good]] = False
    r, words, orient, big = r[good], words[good], orient[good], big[good]
    sec = words[:, 0].astype(np.uint32).view(np.int32).astype(np.int64)  # int32 on the wire
    stamps[r] = sec * 1_000_000_000 + words[:, 1]
    acc = _gather(buf, starts[r] + orient + _ACCEL, 24)
    xyz[r] = np.where(big[:, None], acc.view(">f8"), acc.view("<f8"))
    return fast


def _decode_one(data: bytes) -> tuple[int, tuple[float, float, float]]:
    """One message through the rosbags deserialiser (raises ``ValueError`` when malformed)."""
    from rosbags.serde import SerdeError

    from shm_ros.io.typestore import typestore

    try:
        m: Any = typestore().deserialize_cdr(data, IMU)
    except SerdeError as exc:  # what rosbags raises for any malformed CDR
        raise ValueError(str(exc)) from exc
    la = m.linear_acceleration
    return int(m.header.stamp.sec) * 1_000_000_000 + int(m.header.stamp.nanosec), (la.x, la.y, la.z)
