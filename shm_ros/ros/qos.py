"""QoS of every topic the pipeline touches (documented in docs/topics.md).

- Recording topics (accelerometers, DAQ blocks, temperature) are subscribed with the sensor-data
  profile (best effort), which matches both best-effort and reliable publishers, but with a deep
  history so bursts from a fast replay are not dropped on the floor.
- The pipeline's own topics are reliable and keep all samples up to a bounded depth: a downstream
  node that is briefly busy still gets every window and estimate.
- Windows and modal estimates are also transient-local: a node whose subscription is matched a
  moment after a publication (discovery is not instantaneous, a restarted node comes back late)
  still receives the latest ones. The window publisher keeps only a few (each can be megabytes).
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

RECORDING_DEPTH = 5000
PIPELINE_DEPTH = 100


def recording_qos(depth: int = RECORDING_DEPTH, reliable: bool = False) -> QoSProfile:
    """Subscriptions to recording topics: sensor-data profile (best effort), deep history.

    ``reliable=True`` is for a pipeline fed only by reliable publishers (e.g. ``shm-ros replay``),
    where the DDS flow control then guarantees delivery.
    """
    qos = QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else qos_profile_sensor_data.reliability,
        durability=DurabilityPolicy.VOLATILE,
    )
    return qos


def pipeline_qos(depth: int = PIPELINE_DEPTH) -> QoSProfile:
    """The pipeline's own topics (windows, modal estimates, ...): reliable, volatile."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


WINDOW_HISTORY = 4


def stream_qos(depth: int = PIPELINE_DEPTH) -> QoSProfile:
    """Windows and modal estimates: reliable, transient local (late joiners get the latest)."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def latched_qos(depth: int = 1) -> QoSProfile:
    """Slow-changing results (posterior, verdict, progress): late joiners get the latest."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)
