"""One earthquake event: uniform bidirectional ground acceleration, Newmark (average acceleration).

Returns the true absolute accelerations (x and y) of each floor's accelerometer point and the
peak story drifts and drift velocities in x. ``softening`` (optional) is called every 0.1 s with
the time and the running peak drift per story and returns stiffness factors per story, applied to
the elastic story springs through OpenSees parameters (time-varying secant stiffness).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from . import assemble
from .building import Building
from .opensees import ops
from .story_state import StoryState

Softening = Callable[[float, np.ndarray], np.ndarray]


@dataclass
class EventResponse:
    ax: np.ndarray            # (N, floors) absolute x acceleration at the sensor point of every floor
    ay: np.ndarray
    peak_drift: np.ndarray    # (stories,) m, x
    peak_drift_vel: np.ndarray
    peak_foundation: float    # m, x displacement of the foundation (0 for a fixed base)
    f0_hz: np.ndarray         # small-amplitude frequencies of the state at the start
    k_end: np.ndarray         # stiffness factors at the end (softening) or the state's


def _parameters(b: Building, h: assemble.Handles, state: StoryState) -> dict[int, list[tuple[int, float]]]:
    """Per story: (parameter tag, nominal value) of each line spring's x and y material."""
    out: dict[int, list[tuple[int, float]]] = {}
    tag = 1
    for s, elements in h.story_elements.items():
        out[s] = []
        for j, e in enumerate(elements):
            for m, k in (("1", b.k_x[s] * b.share_x[j]), ("2", b.k_y[s] * b.share_y[j])):
                ops.parameter(tag, "element", e, "material", m, "E")
                out[s].append((tag, float(k)))
                tag += 1
    return out


def _retry(dt: float) -> bool:
    """Substeps and a Krylov-Newton with a looser energy test for a hard step
    back to Newton after."""
    ops.algorithm("KrylovNewton")
    ops.test("EnergyIncr", 1e-12, 100)
    ok = ops.analyze(20, dt / 20) == 0
    ops.algorithm("Newton")
    ops.test("NormDispIncr", 1e-9, 30)
    return ok


def run_event(b: Building, state: StoryState, ag_x: np.ndarray, ag_y: np.ndarray, rate_hz: float,
              softening: Softening | None = None) -> EventResponse:
    h = assemble.build(b, state)
    f0 = assemble.add_rayleigh(b)
    dt = 1.0 / rate_hz
    n = ag_x.size
    linear = state.is_linear() and softening is None
    for tag, (d, rec) in enumerate(((1, ag_x), (2, ag_y)), start=1):
        ops.timeSeries("Path", tag, "-dt", dt, "-values", *rec.tolist())
        ops.pattern("UniformExcitation", tag, d, "-accel", tag)
    ops.constraints("Transformation")
    ops.numberer("RCM")
    ops.system("BandGeneral")
    if linear:
        ops.algorithm("Linear", "-factorOnce")      # constant tangent: one factorisation
    else:
        ops.test("NormDispIncr", 1e-9, 30)
        ops.algorithm("Newton")
    ops.integrator("Newmark", 0.5, 0.25)
    ops.analysis("Transient")
    params = _parameters(b, h, state) if softening is not None else {}
    cm = b.cm_xy()
    dx, dy = b.sensor_xy[0] - cm[0], b.sensor_xy[1] - cm[1]
    acc = np.zeros((n, b.n, 3))
    disp = np.zeros(b.n + 1)
    vel = np.zeros(b.n + 1)
    peak_d, peak_v, peak_f = np.zeros(b.n), np.zeros(b.n), 0.0
    k_now = state.k_factor.copy()
    every = max(1, int(round(0.1 * rate_hz)))
    for i in range(1, n):
        if softening is not None and i % every == 0:
            k_now = softening(i * dt, peak_d)
            for s, plist in params.items():
                for tag, k in plist:
                    ops.updateParameter(tag, k * float(k_now[s]))
        if ops.analyze(1, dt) != 0 and not _retry(dt):
            raise RuntimeError(f"transient analysis failed at t = {i * dt:.2f} s")
        for f, m in enumerate(h.masters):
            acc[i, f] = [ops.nodeAccel(m, 1), ops.nodeAccel(m, 2), ops.nodeAccel(m, 6)]
            disp[f + 1] = ops.nodeDisp(m, 1)
            vel[f + 1] = ops.nodeVel(m, 1)
        if h.foundation is not None:
            disp[0], vel[0] = ops.nodeDisp(h.foundation, 1), ops.nodeVel(h.foundation, 1)
            peak_f = max(peak_f, abs(disp[0]))
        peak_d = np.maximum(peak_d, np.abs(np.diff(disp)))
        peak_v = np.maximum(peak_v, np.abs(np.diff(vel)))
    ax = acc[:, :, 0] - acc[:, :, 2] * dy + ag_x[:, None]   # relative + ground = absolute
    ay = acc[:, :, 1] + acc[:, :, 2] * dx + ag_y[:, None]
    ops.wipe()
    return EventResponse(ax=ax, ay=ay, peak_drift=peak_d, peak_drift_vel=peak_v, peak_foundation=peak_f,
                         f0_hz=f0, k_end=k_now)
