"""Names and types of the pipeline's own topics (recording topics follow docs/interfaces.md §1).

The pipeline's names are relative: they resolve under the node's namespace, so two graphs started
with ``--ros-args -r __ns:=/bridge_a`` and ``-r __ns:=/bridge_b`` (``shm-ros run --namespace``,
the launch file's ``namespace:=``) share one ROS domain without hearing each other. ``/diagnostics``
(and ``/clock``, ``/tf``, ``/tf_static``) are global by ROS convention and stay absolute.
"""

from __future__ import annotations

import importlib

WINDOWS = "shm/windows"  # shm_interfaces/msg/Window, pipeline QoS
MODAL_ESTIMATES = "shm/modal_estimates"  # shm_interfaces/msg/ModalEstimate, pipeline QoS
TRACKED_MODES = "shm/tracked_modes"  # shm_interfaces/msg/TrackedModes
TRACKING_ALARMS = "shm/tracking_alarms"  # shm_interfaces/msg/TrackedModes of alarm windows, latched
POSTERIOR = "shm/posterior"  # shm_interfaces/msg/PosteriorSummary, latched
PREDICTION = "shm/prediction"  # shm_interfaces/msg/ResponsePrediction
VERDICT = "shm/verdict"  # shm_interfaces/msg/Verdict, latched
INGEST_RECEIVED = "shm/ingest/received"  # std_msgs/msg/UInt64: recording messages taken so far
REPLAY_DONE = "shm/replay/done"  # std_msgs/msg/String: bag path, after its last message
PREDICT_REQUEST = "shm/predict_request"  # std_msgs/msg/String: the id of a window to predict
DIAGNOSTICS = "/diagnostics"  # diagnostic_msgs/msg/DiagnosticArray, global

TYPES = {
    WINDOWS: "shm_interfaces/msg/Window",
    MODAL_ESTIMATES: "shm_interfaces/msg/ModalEstimate",
    TRACKED_MODES: "shm_interfaces/msg/TrackedModes",
    TRACKING_ALARMS: "shm_interfaces/msg/TrackedModes",
    POSTERIOR: "shm_interfaces/msg/PosteriorSummary",
    PREDICTION: "shm_interfaces/msg/ResponsePrediction",
    VERDICT: "shm_interfaces/msg/Verdict",
    INGEST_RECEIVED: "std_msgs/msg/UInt64",
    REPLAY_DONE: "std_msgs/msg/String",
    PREDICT_REQUEST: "std_msgs/msg/String",
    DIAGNOSTICS: "diagnostic_msgs/msg/DiagnosticArray",
}


def relative(name: str, namespace: str = "") -> str:
    """A recorded (fully qualified) topic name as the pipeline names it: ``/bridge_a/shm/windows``
    in ``/bridge_a`` and ``/shm/windows`` at the root are both ``shm/windows``; global names
    (``/diagnostics``) and names outside ``namespace`` stay as they are."""
    ns = namespace.rstrip("/")
    if ns and name.startswith(ns + "/"):
        name = name[len(ns):]
    return name[1:] if name.startswith("/") and name[1:] in TYPES else name


def type_of(name: str) -> str | None:
    """The message type of a pipeline topic given relative or absolute (``/shm/windows``); None if unknown."""
    return TYPES.get(name) or TYPES.get(name.lstrip("/"))


def message_class(msgtype: str) -> type:
    """``"sensor_msgs/msg/Imu"`` -> the rclpy class; ImportError/AttributeError when unknown."""
    pkg, _, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)
