"""Message <-> dataclass conversion, in one place.

Works on rclpy message classes (``shm_interfaces.msg``); numpy arrays are assigned to array fields
directly (no per-element Python loops on the 6 MB windows).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from shm_ros.core.ingest.events import window_event_kind
from shm_ros.core.timeutil import join_ns, split_ns
from shm_ros.core.types import ModalEstimate, Mode, Window


def time_to_ns(t: Any) -> int:
    """``builtin_interfaces/Time`` (a ``header.stamp``) -> ns since the epoch."""
    return join_ns(t.sec, t.nanosec)


def ns_to_time(t_ns: int, cls: type | None = None) -> Any:
    if cls is None:
        from builtin_interfaces.msg import Time

        cls = Time
    sec, nsec = split_ns(t_ns)
    return cls(sec=sec, nanosec=nsec)


def _set_temperature(msg: Any, temperature_c: float | None) -> None:
    if temperature_c is not None and math.isfinite(temperature_c):
        msg.has_temperature, msg.temperature_c = True, float(temperature_c)
    else:
        msg.has_temperature, msg.temperature_c = False, float("nan")


def _get_temperature(msg: Any) -> float | None:
    return float(msg.temperature_c) if msg.has_temperature else None


def window_to_msg(w: Window, frame_id: str = "") -> Any:
    from shm_interfaces.msg import Window as WindowMsg

    msg = WindowMsg()
    msg.header.stamp = ns_to_time(w.start_ns)
    msg.header.frame_id = frame_id
    msg.window_id = w.window_id
    msg.start = ns_to_time(w.start_ns)
    msg.end = ns_to_time(w.end_ns)
    msg.sample_rate_hz = float(w.sample_rate_hz)
    msg.channel_names = list(w.channel_names)
    msg.n_samples = w.n_samples
    msg.samples = np.ascontiguousarray(w.samples, dtype=np.float64).reshape(-1)
    if w.flags is not None and np.any(w.flags):
        msg.flags = np.ascontiguousarray(w.flags, dtype=np.uint8).reshape(-1)
    msg.channel_status = list(w.channel_status or [])
    _set_temperature(msg, w.temperature_c)
    msg.is_event = bool(w.is_event)
    msg.pga_m_s2 = float(w.pga_m_s2)
    msg.input_channel = w.input_channel or ""
    msg.notes = list(w.notes)
    return msg


def window_from_msg(msg: Any) -> Window:
    n, c = int(msg.n_samples), len(msg.channel_names)
    samples = np.frombuffer(msg.samples, dtype=np.float64) if len(msg.samples) else np.zeros(0)
    if samples.size != n * c:
        raise ValueError(f"Window {msg.window_id!r}: samples has {samples.size} values, "
                         f"expected n_samples*channels = {n}*{c}")
    flags = None
    if len(msg.flags):
        flags = np.frombuffer(msg.flags, dtype=np.uint8)
        if flags.size != n * c:
            raise ValueError(f"Window {msg.window_id!r}: flags has {flags.size} values, expected {n * c}")
        flags = flags.reshape(n, c).copy()
    w = Window(
        window_id=msg.window_id,
        start_ns=time_to_ns(msg.start),
        sample_rate_hz=float(msg.sample_rate_hz),
        channel_names=list(msg.channel_names),
        samples=samples.reshape(n, c).copy(),
        flags=flags,
        channel_status=list(msg.channel_status) or None,
        temperature_c=_get_temperature(msg),
        is_event=bool(msg.is_event),
        pga_m_s2=float(msg.pga_m_s2),
        input_channel=msg.input_channel or None,
        notes=list(msg.notes),
    )
    w.event_kind = window_event_kind(w).value  # the message does not carry it: named with the ingest defaults
    return w


def mode_to_msg(m: Mode) -> Any:
    from shm_interfaces.msg import Mode as ModeMsg

    return ModeMsg(
        frequency_hz=float(m.frequency_hz), damping_ratio=float(m.damping_ratio), mpc=float(m.mpc),
        frequency_std_hz=float(m.frequency_std_hz), damping_std=float(m.damping_std),
        n_poles=int(m.n_poles), mode_shape=np.asarray(m.mode_shape, dtype=np.float64),
        mode_number=int(m.mode_number),
    )


def mode_from_msg(msg: Any) -> Mode:
    return Mode(
        frequency_hz=msg.frequency_hz, damping_ratio=msg.damping_ratio,
        mode_shape=np.array(msg.mode_shape, dtype=np.float64), mpc=msg.mpc,
        frequency_std_hz=msg.frequency_std_hz, damping_std=msg.damping_std,
        n_poles=int(msg.n_poles), mode_number=int(msg.mode_number),
    )


def estimate_to_msg(e: ModalEstimate, frame_id: str = "") -> Any:
    from shm_interfaces.msg import ModalEstimate as EstimateMsg

    msg = EstimateMsg()
    msg.header.stamp = ns_to_time(e.start_ns)
    msg.header.frame_id = frame_id
    msg.window_id = e.window_id
    msg.start = ns_to_time(e.start_ns)
    msg.end = ns_to_time(e.end_ns)
    _set_temperature(msg, e.temperature_c)
    msg.method = e.method
    msg.sensor_ids = list(e.sensor_ids)
    msg.modes = [mode_to_msg(m) for m in e.modes]
    msg.covariate_names = list(e.covariates)
    msg.covariate_values = [float(v) for v in e.covariates.values()]
    return msg


def estimate_from_msg(msg: Any) -> ModalEstimate:
    return ModalEstimate(
        window_id=msg.window_id, start_ns=time_to_ns(msg.start), end_ns=time_to_ns(msg.end),
        sensor_ids=list(msg.sensor_ids), modes=[mode_from_msg(m) for m in msg.modes],
        method=msg.method, temperature_c=_get_temperature(msg),
        # a message from another publisher may be malformed: extra names or values are dropped
        covariates=dict(zip(msg.covariate_names, (float(v) for v in msg.covariate_values), strict=False)),
    )


def tracked_row_to_msg(row: Any, frame_id: str = "") -> Any:
    """:class:`shm_ros.core.tracking.TrackedRow` -> ``TrackedModes`` (NaN = mode not found)."""
    from shm_interfaces.msg import TrackedModes

    msg = TrackedModes()
    msg.header.stamp = ns_to_time(row.start_ns)
    msg.header.frame_id = frame_id
    msg.window_id = row.window_id
    msg.time = ns_to_time(row.start_ns)
    msg.mode_numbers = [int(k) for k in row.mode_numbers]
    msg.frequencies_hz = [float(v) for v in row.frequencies_hz]
    msg.damping_ratios = [float(v) for v in row.damping]
    msg.macs_to_reference = [float(v) for v in row.macs]
    msg.sensor_ids = list(row.sensor_ids)
    msg.mode_shapes = [float(v) for v in np.asarray(row.shapes, dtype=float).ravel()]
    msg.covariate_names = list(row.covariates)
    msg.covariate_values = [float(v) for v in row.covariates.values()]
    msg.novelty_score = float(row.novelty_score)
    msg.novelty_threshold = float(row.novelty_threshold)
    msg.novelty_alarm = bool(row.novelty_alarm)
    return msg


def posterior_to_msg(record: dict[str, Any]) -> Any:
    """``Posterior.summary_record()`` (the message's fields by name) -> ``PosteriorSummary``."""
    from shm_interfaces.msg import ParameterEstimate, PosteriorSummary

    msg = PosteriorSummary()
    for key, value in record.items():
        if key == "parameters":
            msg.parameters = [ParameterEstimate(**{k: (float(v) if k != "name" else v)
                                                   for k, v in p.items()}) for p in value]
        elif key == "warnings":
            msg.warnings = [str(w) for w in value]
        else:
            setattr(msg, key, value)
    return msg


def tracked_row_from_msg(msg: Any) -> Any:
    """``TrackedModes`` -> :class:`shm_ros.core.tracking.TrackedRow` (the fields the updating uses)."""
    from shm_ros.core.tracking import TrackedRow

    n_m, sensors = len(msg.mode_numbers), list(msg.sensor_ids)
    shapes = np.asarray(msg.mode_shapes, dtype=np.float64)
    if shapes.size != n_m * len(sensors):  # malformed: no shapes rather than misplaced ones
        shapes = np.full(n_m * len(sensors), np.nan)
    return TrackedRow(msg.window_id, time_to_ns(msg.time), [int(k) for k in msg.mode_numbers],
                      np.asarray(msg.frequencies_hz, dtype=np.float64),
                      np.asarray(msg.damping_ratios, dtype=np.float64),
                      np.asarray(msg.macs_to_reference, dtype=np.float64), sensors,
                      shapes.reshape(n_m, len(sensors)),
                      dict(zip(msg.covariate_names, (float(v) for v in msg.covariate_values), strict=False)))
