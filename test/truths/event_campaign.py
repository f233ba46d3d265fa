"""An event campaign: 5-30 earthquakes over months recorded by a ground (free-field) sensor and floor
accelerometers of a 3-D building, one effect (``event_effects.py``) and realistic nuisance.

Nuisance in every campaign: the building's stiffness varies from event to event by 0.3 % (RMS
the
temperature on the day), the sensors have gain, misalignment and noise (``sensors.py``), each
event has its own synthetic ground motion (``ground_motion.py``) with a y component of 50-90 % of
x, and PGAs span a factor 12-30 (log-uniform between the extremes).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .building import draw_building
from .event_effects import EFFECTS, Context
from .files import iso, write_event_bag, write_truth, write_yaml
from .ground_motion import GroundMotion
from .nominal import building_document
from .sensors import SensorErrors
from .story_state import StoryState
from .transient import run_event

NUISANCE_STIFFNESS = 0.003


@dataclass(frozen=True)
class EventSize:
    stories: tuple[int, int]      # inclusive range
    events: tuple[int, int]
    duration_s: tuple[float, float]
    rates_hz: tuple[float, ...]
    span_days: tuple[float, float]


SIZES = {"reduced": EventSize((1, 2), (5, 5), (21.0, 21.0), (50.0,), (60.0, 60.0)),
         "full": EventSize((3, 10), (8, 30), (20.0, 60.0), (100.0, 200.0), (120.0, 540.0))}


def _schedule(rng: np.random.Generator, m: int, span_days: float) -> np.ndarray:
    gaps = rng.exponential(1.0, m)
    t = np.cumsum(gaps) / gaps.sum() * span_days * 86400.0
    t = np.maximum(t, np.arange(1, m + 1) * 86400.0)  # from day 1
    for k in range(1, m):  # at least an hour apart: a short exponential gap overlapped two records
        t[k] = max(t[k], t[k - 1] + 3600.0)
    return t


def _pgas(rng: np.random.Generator, m: int) -> tuple[np.ndarray, float]:
    lo, ratio = float(rng.uniform(0.05, 0.12)), float(rng.uniform(12.0, 30.0))
    u = rng.uniform(0, 1, m)
    u[np.argmin(u)], u[np.argmax(u)] = 0.0, 1.0
    return lo * ratio**u, ratio


def generate(kind: str, seed: int, size: str, out: Path) -> dict:
    """Write ``out/structure.yaml``, ``out/events`` (bag) and ``out/truth.json``
    returns the truth."""
    rng = np.random.default_rng(seed)
    sz = SIZES[size]
    effect = EFFECTS[kind]()
    n = int(rng.integers(sz.stories[0], sz.stories[1] + 1))
    m = int(rng.integers(sz.events[0], sz.events[1] + 1))
    rate = float(rng.choice(sz.rates_hz))
    b = draw_building(rng, n)
    times = _schedule(rng, m, float(rng.uniform(*sz.span_days)))
    pga, ratio = _pgas(rng, m)
    strong = int(np.argmax(pga))
    if effect.wants_strong_in_middle:
        j = max(1, m // 2 - 1)
        pga[[j, strong]] = pga[[strong, j]]
        strong = j
        if kind == "event_transient_softening" and j + 2 < m:   # aftershocks hours and a day later
            times[j + 1] = times[j] + rng.uniform(1.0, 4.0) * 3600.0
            times[j + 2] = times[j] + rng.uniform(12.0, 36.0) * 3600.0
            pga[j + 1], pga[j + 2] = pga.min() * rng.uniform(1.5, 3.0), pga.min() * rng.uniform(1.5, 3.0)
    motions = [GroundMotion.draw(rng, float(rng.uniform(*sz.duration_s))) for _ in range(m)]
    y_ratio = rng.uniform(0.5, 0.9, m)
    ground = [(g.record(rng, rate, p), g.record(rng, rate, p * yr))
              for g, p, yr in zip(motions, pga, y_ratio, strict=True)]
    linear_strong = run_event(b, StoryState.clean(n), *ground[strong], rate)
    # the effect draws from its own stream: the campaign of another effect (or the clean one) with the
    # same seed has the same building, ground motions, nuisance and sensor errors (common random numbers)
    ctx = Context(building=b, times_s=times, pga=pga, strong=strong, linear_strong=linear_strong,
                  rng=np.random.default_rng([seed, 1]))
    effect.prepare(ctx)
    channels = ["g0", *[f"f{f}" for f in b.instrumented]]
    errors = SensorErrors.draw(rng, len(channels))
    events, per_event = [], []
    for i in range(m):
        state = effect.state(i)
        nuisance = 1.0 + NUISANCE_STIFFNESS * float(rng.standard_normal())
        state.k_factor = state.k_factor * nuisance
        r = run_event(b, state, *ground[i], rate, softening=effect.softening(i, ctx, state.k_factor))
        effect.after_event(i, r)
        floors = [f - 1 for f in b.instrumented]
        ax = np.column_stack([ground[i][0], r.ax[:, floors]])
        ay = np.column_stack([ground[i][1], r.ay[:, floors]])
        events.append((float(times[i]), rate, channels, errors.read(rng, ax, ay)))
        per_event.append({"time": iso(times[i]), "pga_x_m_s2": float(pga[i]), "pga_y_m_s2": float(pga[i] * y_ratio[i]),
                          "duration_s": motions[i].duration_s, "ground_frequency_hz": motions[i].fg,
                          "nuisance_stiffness_factor": nuisance,
                          "small_amplitude_frequencies_hz": r.f0_hz[:3].tolist(),
                          "peak_drift_m": r.peak_drift.tolist(), "stiffness_factor_end": r.k_end.tolist()})
    out.mkdir(parents=True, exist_ok=True)
    k_add, c_add = effect.designed()
    doc = building_document(b, rng, f"truth-{kind}-{seed}", k_add, c_add)
    write_yaml(doc, out / "structure.yaml")
    write_event_bag(out / "events", events)
    truth = {"kind": kind, "seed": seed, "size": size, "expected": effect.expected,
             "acceptable": list(effect.acceptable), "effect": effect.truth(),
             "change_time": iso(times[effect.change_event]) if effect.change_event is not None else None,
             "pga_ratio": float(pga.max() / pga.min()), "rate_hz": rate, "channels": channels,
             "building": {"stories": n, "masses_kg": b.masses, "k_x_N_m": b.k_x, "k_y_N_m": b.k_y,
                          "plan_m": b.plan, "cm_offset_m": b.cm_offset, "rayleigh_ratios": b.zeta,
                          "damper_c_N_s_m": b.damper_c, "sensor_xy_m": b.sensor_xy,
                          "instrumented_floors": b.instrumented},
             "sensor_errors": errors.as_dict(), "events": per_event}
    write_truth(truth, out / "truth.json")
    return truth
