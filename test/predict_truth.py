"""Truth campaigns for the prediction's acceptance tests: calibration events, predicted events, and
the truth's responses at floors no sensor reads and its story drift ratios.

A truth source is a function ``(seed, profile) -> PredictCampaign``; the registry ``SOURCES`` names
them and ``SHM_PREDICT_TRUTH`` picks the one the tests use (else each test's default: ``opensees``
for the acceptance of the bands, ``simulator`` where a test sets the events' PGAs and onsets).

``opensees``: the independent OpenSeesPy generator (``test/truths``, adapter
test/predict_opensees.py): hysteretic story springs that yield in the strongest events, centre of
mass 2-6 % off, non-proportional damping, a damper; the nominal planar model is the generator's.

``simulator``: the project's simulator (``shm_ros.core.simulate``) outside the analysis class -
x, y and twist per floor with mass centres 2-6 % of the plan off the stiffness centre (at and above
the codes' 5 % accidental eccentricity), a flexural component, story dashpots spread lognormally
around the stiffness-proportional law (non-proportional damping), Kelvin-Voigt damper braces,
softening story springs (``amplitude_stiffness``, f = k d / (1 + |d| / d_ref), integrated by
Newmark with Newton iterations) and velocity-dependent dashpots; sensor gains, offsets, misalignment
and noise; unmeasured y ground motion and wind. The analysis structure is the nominal planar file
with story stiffnesses 10-20 % off (test/predict_synth.py). The truth's drifts are the story
drifts of the nonlinear run at the stiffness centre.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from predict_synth import STORY_HEIGHT_M, quake_campaign

from shm_ros.core.simulate.scenario import EffectRequest
from shm_ros.core.simulate.truths.shear_building import HISTORIES
from shm_ros.core.types import Window

# the story springs f = k d / (1 + |d| / d_ref) have lost 10 % of their secant stiffness at this
# share of d_ref: beyond it a story has left the elastic range a linear model assumes
ELASTIC_SHARE = 0.1 / 0.9


@dataclass
class PredictCampaign:
    structure: dict[str, Any]  # the analysis structure file (mapping)
    calibration: list[Window]
    predicted: list[Window]
    # per predicted window id: truth name -> (N,) series; names "floor<k>" (absolute acceleration,
    # m/s^2) for floors no sensor reads and "drift_ratio<k>" for every story k
    truth: dict[str, dict[str, np.ndarray]]
    yields: dict[str, bool] = field(default_factory=dict)  # per window: the truth left its elastic range
    elastic_drift_ratio: float = 0.0  # the truth's elastic limit (drift ratio)


@dataclass(frozen=True)
class Profile:
    n_calibration: int = 3
    n_predicted: int = 3
    duration_s: float = 40.0
    fs: float = 40.0
    sensor_floors: tuple[int, ...] = (2, 4, 6, 8)
    eccentricity: tuple[float, float] = (0.02, 0.06)
    pga_m_s2: tuple[float, float] = (0.3, 1.5)
    drift_ref_m: float = 0.06  # softening story springs: k / (1 + |d| / d_ref)
    earthquakes: tuple[tuple[float, float], ...] = ()  # (pga m/s^2, onset s) per event; () = drawn
    stories: tuple[int, int] = (3, 8)  # OpenSees source: stories drawn in this range (inclusive)


def simulator_campaign(seed: int, profile: Profile | None = None) -> PredictCampaign:
    """The simulator's truth (module doc)."""
    profile = profile or Profile()
    n = profile.n_calibration + profile.n_predicted
    hidden = tuple(range(1, 9))
    effects = [EffectRequest("amplitude_stiffness", {"drift_ref_m": profile.drift_ref_m}),
               EffectRequest("amplitude_damping", {})]
    options: dict[str, Any] = {"eccentricity": profile.eccentricity, "pga_range_m_s2": profile.pga_m_s2}
    if profile.earthquakes:
        options["earthquakes"] = [{"window": i, "pga_m_s2": p, "onset_s": t}
                                  for i, (p, t) in enumerate(profile.earthquakes)]
    camp, structure, _ = quake_campaign(seed, n, duration_s=profile.duration_s, fs=profile.fs,
                                        sensor_floors=profile.sensor_floors, truth_floors=hidden, effects=effects,
                                        **options)
    keep = [s["id"] for s in structure["sensors"]]
    rerun = replace(camp, truth_model=replace(camp.truth_model, keep_histories=True))
    windows, truth, yields = [], {}, {}
    for i in range(n):
        sw = (rerun if i >= profile.n_calibration else camp).window(i)
        w = sw.to_window()
        w = replace(w, channel_names=keep, samples=w.samples[:, [w.channel_names.index(s) for s in keep]])
        windows.append(w)
        if i < profile.n_calibration:
            continue
        t = {f"floor{k}": sw.accel[:, sw.sensor_ids.index(f"h{k}")] for k in hidden
             if k not in profile.sensor_floors}
        drift = np.asarray(sw.truth.pop(HISTORIES)["story_drift"])[:, 0::3]  # x at the stiffness centre
        for k in range(drift.shape[1]):
            t[f"drift_ratio{k + 1}"] = drift[:, k] / STORY_HEIGHT_M
        truth[w.window_id] = t
        yields[w.window_id] = float(np.max(np.abs(drift))) > ELASTIC_SHARE * profile.drift_ref_m
    return PredictCampaign(structure, windows[:profile.n_calibration], windows[profile.n_calibration:], truth,
                           yields, ELASTIC_SHARE * profile.drift_ref_m / STORY_HEIGHT_M)


def opensees_campaign(seed: int, profile: Profile | None = None) -> PredictCampaign:
    """The independent OpenSeesPy truth (test/predict_opensees.py)."""
    from predict_opensees import opensees_campaign as make

    return make(seed, profile)


SOURCES: dict[str, Callable[..., PredictCampaign]] = {"simulator": simulator_campaign, "opensees": opensees_campaign}


def truth_source(default: str = "simulator") -> Callable[..., PredictCampaign]:
    """The truth source ``SHM_PREDICT_TRUTH`` names (else ``default``)."""
    name = os.environ.get("SHM_PREDICT_TRUTH", default)
    if name not in SOURCES:
        raise KeyError(f"SHM_PREDICT_TRUTH={name!r}: one of {sorted(SOURCES)}")
    return SOURCES[name]
