"""An event (or any window) as a prediction needs it: the input records and the measured outputs."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from shm_ros.core.models.base import AffineModel
from shm_ros.core.types import Window
from shm_ros.errors import InputError


@dataclass
class EventRecord:
    """``inputs`` (n_inputs, N) in the order of ``model.inputs``; ``outputs`` (N, c) raw values of
    ``channel_ids`` (NaN where nothing was recorded); both as recorded (offsets included)."""

    window_id: str
    start_ns: int
    fs: float
    inputs: np.ndarray
    outputs: np.ndarray
    channel_ids: list[str]
    is_event: bool = True
    pga_m_s2: float = 0.0
    notes: list[str] = field(default_factory=list)

    @property
    def n_samples(self) -> int:
        return int(self.inputs.shape[1])


def event_from_window(window: Window, model: AffineModel) -> EventRecord:
    """The model's input sensors and the output sensors it observes, from ``window``.

    The model is driven from rest at the window's start: a stretch where an input is not finite
    cannot be bridged, so the longest clean stretch of the inputs is kept (and said so).
    """
    ins = [i.sensor for i in model.inputs]
    if not ins:
        raise ValueError(f"model {model.name!r}: prediction needs the structure's measured input(s) ('inputs')")
    missing = [s for s in ins if s not in window.channel_names]
    if missing:
        raise InputError(f"window {window.window_id}: no record of the input sensor(s) {missing}")
    outs = [s for s in window.channel_names if s in model.sensor_rows and s not in ins]
    col = {c: k for k, c in enumerate(window.channel_names)}
    u = np.asarray(window.samples[:, [col[s] for s in ins]], dtype=float).T
    y = np.asarray(window.samples[:, [col[s] for s in outs]], dtype=float)
    notes: list[str] = []
    good = np.all(np.isfinite(u), axis=0)
    start_ns = window.start_ns
    if not good.all():
        edges = np.flatnonzero(np.diff(np.concatenate([[0], good.astype(int), [0]]))).reshape(-1, 2)
        a, b = edges[np.argmax(edges[:, 1] - edges[:, 0])] if edges.size else (0, 0)
        if b - a < 2:
            raise InputError(f"window {window.window_id}: the input record has no clean stretch")
        u, y = u[:, a:b], y[a:b]
        start_ns += int(round(a * 1e9 / window.sample_rate_hz))
        notes.append(f"input not finite everywhere: samples {a}..{b} used")
    return EventRecord(window.window_id, int(start_ns), float(window.sample_rate_hz), u, y, outs,
                       bool(window.is_event), float(window.pga_m_s2), notes)
