"""The OpenSeesPy truth (``test/truths``) as a prediction campaign: a thin adapter, no physics here.

``opensees_campaign(seed, profile)`` generates one ``event_hysteretic`` campaign of the independent
generator (3-D building on rigid diaphragms, centre of mass 2-6 % of the plan off, Rayleigh damping
plus a viscous damper in one story - non-proportional -, Steel02 story springs yielding at a third
to a fifth of the strongest event's linear drift; sensor gain, misalignment and noise; nominal
planar model with +-5 % stiffness and +-2 % mass errors) with as many events as the profile
calibrates and predicts, and reads it back through the project's public readers (the bag through
``windows_from_bag``, the structure YAML). The campaign size is the generator's own ``EventSize``
with the profile's event count, record length and rate; the stories (3-8 at full size) leave
floors no sensor reads. The calibration's parameters are the generator's story groups plus the
Rayleigh ratio (lognormal around the nominal, as an engineer calibrating on earthquake records
would: the nominal ratio is a guess and strong shaking dissipates more), so the analysis is the
project's planar model with the parameters a time-domain calibration needs.

The truth the bag does not hold is recorded while the generator runs, by wrapping its
``run_event`` (the same call, its result passed on unchanged): the true absolute x acceleration of
every floor at the sensors' plan point (``floor<k>`` for the floors without a sensor) and the
peak story drift in x at the centre of mass (``drift_ratio<k>``: a one-sample series holding the
peak, which is all the scores read). A window ``yields`` where a story's peak drift passes its
spring's yield drift.
"""

from __future__ import annotations

import contextlib
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from predict_truth import PredictCampaign, Profile
from truths import event_campaign

from shm_ros.io.recording import windows_from_bag

KIND = "event_hysteretic"
DAMPING = {"name": "zeta", "applies_to": "damping.ratios[*]", "prior": {"dist": "lognormal", "mean": 1.0, "std": 0.5}}


@contextlib.contextmanager
def _recorded_runs() -> Iterator[list[Any]]:
    """Every ``run_event`` result of a generation, in call order (first the effect's linear run of
    the strongest event, then one per event)."""
    runs: list[Any] = []
    original = event_campaign.run_event

    def recording(*args: Any, **kwargs: Any) -> Any:
        r = original(*args, **kwargs)
        runs.append(r)
        return r

    event_campaign.run_event = recording
    try:
        yield runs
    finally:
        event_campaign.run_event = original


def _size(profile: Profile) -> str:
    """Register (once) the generator size of this profile; its name."""
    m = profile.n_calibration + profile.n_predicted
    name = f"predict-{profile.stories[0]}-{profile.stories[1]}-{m}-{profile.duration_s:g}-{profile.fs:g}"
    event_campaign.SIZES.setdefault(name, event_campaign.EventSize(
        profile.stories, (m, m), (profile.duration_s, profile.duration_s), (profile.fs,), (60.0, 240.0)))
    return name


def opensees_campaign(seed: int, profile: Profile | None = None) -> PredictCampaign:
    """The OpenSeesPy truth (module doc)."""
    profile = profile or Profile()
    with tempfile.TemporaryDirectory(prefix="shm-predict-truth-") as tmp, _recorded_runs() as runs:
        out = Path(tmp)
        truth = event_campaign.generate(KIND, seed, _size(profile), out)
        structure = yaml.safe_load((out / "structure.yaml").read_text())
        structure["parameters"].append(dict(DAMPING))
        windows, _ = windows_from_bag(out / "events", out / "structure.yaml")
    events = runs[1:]
    if len(windows) != len(events):
        raise RuntimeError(f"truth campaign {seed}: {len(windows)} windows for {len(events)} events")
    windows = sorted(windows, key=lambda w: w.start_ns)
    b = truth["building"]
    heights = np.asarray([f["height"] for f in structure["shear_building"]["floors"]], float)
    yield_drift = np.asarray(truth["effect"]["magnitudes"]["yield_drift_m"], float)
    measured = set(b["instrumented_floors"])
    nc = profile.n_calibration
    out_truth: dict[str, dict[str, np.ndarray]] = {}
    yields: dict[str, bool] = {}
    for w, r in zip(windows[nc:], events[nc:], strict=True):
        t = {f"floor{k}": np.asarray(r.ax[:, k - 1]) for k in range(1, b["stories"] + 1) if k not in measured}
        for k, d in enumerate(np.asarray(r.peak_drift, float)):
            t[f"drift_ratio{k + 1}"] = np.array([d / heights[k]])
        out_truth[w.window_id] = t
        yields[w.window_id] = bool(np.any(np.asarray(r.peak_drift) > yield_drift))
    return PredictCampaign(structure, windows[:nc], windows[nc:], out_truth, yields,
                           float(np.min(yield_drift / heights)))
