"""Event series for the time-domain explain tests: earthquakes on the eight-story building of the
prediction tests (:mod:`predict_synth`: the simulator's truth with its default model-form error, damper
braces, nominal story stiffnesses 10-20 % off), with an amplitude effect or none.

Six events (PGA 0.25-1.6 m/s^2, a factor 6.4, in an order drawn per seed) of 60 s each. The effects are
the simulator's own, outside the analysis model's class: softening story springs
``f = k d / (1 + |d| / d_ref)`` (``amplitude_stiffness``, Newmark with Newton iterations; the stiffness
changes within an event with the drift) and story dashpots ``f = c v (1 + |v| / v_ref)``
(``amplitude_damping``).

**The truth's equivalent of a candidate's parameter.** Per event, the simulator's equivalent-linear
truth over the strong motion (5-95 % of the ground motion's Arias intensity, the samples the amplitude
covariate is measured on; the mean-square secant stiffness and damping of every story,
:mod:`shm_ros.core.simulate.equivalent_linear`) gives the first in-plane mode's frequency ``f1_e`` and
damping ratio ``z1_e``; without the effect they are ``f1_0``, ``z1_0``. Stiffness: the factor a
uniform stiffness change needs to move f1 alike, ``s_e = (f1_e / f1_0)^2``; damping: the factor on the
analysis model's inherent damping (first-mode ratio ``zeta_inh``) that adds the same first-mode damping,
``d_e = 1 + (z1_e - z1_0) / zeta_inh``. The same form as the candidate (``1 / (1 + k a)`` resp.
``1 + k a``, ``a`` the event's amplitude covariate as the method computes it) is fitted to these by
least squares; its ``k`` is the truth's equivalent.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from predict_synth import quake_campaign
from scipy.optimize import minimize_scalar

from shm_ros.core.models import build_model
from shm_ros.core.predict import EventRecord, event_from_window
from shm_ros.core.predict.signals import strong_motion
from shm_ros.core.simulate.equivalent_linear import simulate_event
from shm_ros.core.simulate.scenario import EffectRequest
from shm_ros.core.structure import structure_from_dict

PGAS = (0.25, 0.4, 0.6, 0.85, 1.2, 1.6)
EFFECTS = {"amplitude_dependent_stiffness": ("amplitude_stiffness", {"drift_ref_m": 0.01}),
           "amplitude_dependent_damping": ("amplitude_damping", {"velocity_ref_m_s": 0.02})}


@dataclass
class EventSeries:
    structure: dict[str, Any]
    events: list[EventRecord]
    name: str | None  # vocabulary name of the effect (None: clean)
    f1_0: float  # small-amplitude first in-plane frequency of the truth
    z1_0: float
    f1: np.ndarray  # (E,) equivalent-linear first frequency per event (f1_0 when clean)
    z1: np.ndarray


def event_series(seed: int, name: str | None, *, n_events: int = 6, duration_s: float = 60.0,
                 fs: float = 40.0, pgas: tuple[float, ...] = PGAS) -> EventSeries:
    rng = np.random.default_rng(np.random.SeedSequence([seed, 515]))
    order = rng.permutation(n_events)
    quakes = [{"window": i, "pga_m_s2": float(pgas[order[i] % len(pgas)]),
               "onset_s": float(rng.uniform(0.15, 0.3) * duration_s)} for i in range(n_events)]
    eff = [EffectRequest(*EFFECTS[name])] if name else []
    camp, structure, _ = quake_campaign(seed, n_events, duration_s=duration_s, fs=fs, sensor_floors=(2, 4, 6, 8),
                                        effects=eff, earthquakes=quakes)
    model = build_model(structure_from_dict(structure))
    keep = [s["id"] for s in structure["sensors"]]
    events, f1, z1 = [], [], []
    f1_0 = z1_0 = float("nan")
    for i in range(n_events):
        if name:
            ev = simulate_event(camp, i)
            w = ev.window
            sm = strong_motion(ev.window.samples[:, ev.window.channel_names.index("g0")])
            tr = ev.track(np.array([sm.start / ev.fs]), (min(sm.stop, ev.story_drift_m.shape[0]) - sm.start) / ev.fs)
            f1_0, z1_0 = float(ev.small_amplitude_frequencies_hz[0]), float(ev.small_amplitude_damping[0])
            f1.append(float(tr.frequencies_hz[0, 0]))
            z1.append(float(tr.damping_ratios[0, 0]))
        else:
            w = camp.window(i).to_window()
        cols = [w.channel_names.index(s) for s in keep]
        w.channel_names, w.samples = keep, w.samples[:, cols]
        events.append(event_from_window(w, model))
    if not name:
        f1, z1 = [f1_0] * n_events, [z1_0] * n_events
    return EventSeries(structure, events, name, f1_0, z1_0, np.array(f1), np.array(z1))


def truth_parameter(series: EventSeries, amplitude: np.ndarray, zeta_inh: float | None = None) -> float:
    """The truth's equivalent ``k`` of the candidate's form (module doc) for the events' amplitudes."""
    a = np.asarray(amplitude, float)
    if series.name == "amplitude_dependent_stiffness":
        s = (series.f1 / series.f1_0) ** 2
        r = minimize_scalar(lambda k: float(np.sum((1.0 / (1.0 + k * a) - s) ** 2)), bounds=(0.0, 100.0 / a.max()),
                            method="bounded", options={"xatol": 1e-10})
        return float(r.x)
    if series.name == "amplitude_dependent_damping":
        assert zeta_inh is not None
        d = 1.0 + (series.z1 - series.z1_0) / zeta_inh
        return float(np.sum(a * (d - 1.0)) / np.sum(a * a))
    return 0.0
