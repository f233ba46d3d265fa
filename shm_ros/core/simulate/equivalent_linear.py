"""Time-resolved truth of an event: equivalent-linear modal properties of moving windows.

During an earthquake the softening story springs ``f = k d / (1 + |d| / d_ref)`` of
:mod:`shm_ros.core.simulate.newmark` make the modes move within the record. The truth of one
window ``[a, b)`` of the response is the linear model whose story row ``i`` (x, y and twist of
every story with the building's model form) has the *mean-square secant stiffness* of that
window's drift history

    k_eq,i = sum_t d_i(t) f_i(d_i(t)) / sum_t d_i(t)^2
           = k_i sum_t d_i^2 / (1 + |d_i| / d_ref) / sum_t d_i^2

(the least-squares straight line through the window's force-drift points; the same linearisation
for amplitude-dependent story dashpots with the drift velocity). For a Gaussian drift it equals the
window factor of the simulator (``E[g'(d)]``, Stein's lemma), but it needs no Gaussian or stationary
response: a window that straddles the strong shaking and the quiet before it, or a free decay, has
the stiffness its samples actually carry, weighted by their squared amplitude as a least-squares
identification weights them. The frequencies and damping ratios are those of the truth model's
state space with these stiffness and damping factors (:meth:`BuildingTruth.system`), of one mode
family (default the in-plane one, ``x`` for the building's x sensors: the modes the analysis model
describes; y sway and torsion are the truth's own).

:func:`simulate_event` is the campaign's own window (:meth:`Campaign.window`) run on a copy of the
truth that also returns the story drift histories, so the record is the campaign's, sample for
sample.
"""


from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shm_ros.core.simulate.campaign import AMPLITUDE_EFFECTS, Campaign, single_blas_thread
from shm_ros.core.simulate.truths.shear_building import HISTORIES, BuildingTruth
from shm_ros.core.types import Window

__all__ = ["EquivalentLinearTrack", "EventSimulation", "secant_factors", "equivalent_linear_track",
           "simulate_event"]


@dataclass
class EquivalentLinearTrack:
    """Equivalent-linear truth of windows ``[start_s, start_s + length_s)`` of an event record."""

    start_s: np.ndarray  # (w,) window starts, s from the record start
    length_s: float
    story_drift_rms_m: np.ndarray  # (w, n_rows) per story row (x, y, twist of every story: model form)
    stiffness_factor: np.ndarray  # (w, n_rows) k_eq / k
    damping_factor: np.ndarray  # (w, n_rows) c_eq / c
    frequencies_hz: np.ndarray  # (w, n_modes) the family's modes, ascending
    damping_ratios: np.ndarray  # (w, n_modes)
    family: str = ""  # the mode family followed ("": every reported mode)


@dataclass
class EventSimulation:
    """One simulated event window with what the truth needs to follow it in time."""

    window: Window  # what the sensors recorded (as ``SimulatedWindow.to_window``)
    fs: float
    story_drift_m: np.ndarray  # (n, n_rows) after warm-up, per story row (x, y, twist: model form)
    story_velocity_m_s: np.ndarray  # (n, n_rows)
    truth: Any  # the campaign's truth model (``BuildingTruth``)
    factors: dict[str, float]
    drift_ref_m: float | None  # None: linear story springs
    velocity_ref_m_s: float | None  # None: linear story dashpots
    stiffness_nonlinear: np.ndarray  # (n_rows,) bool: softening spring (a foundation's stays linear)
    damping_nonlinear: np.ndarray  # (n_rows,) bool
    event: dict[str, float] | None
    family: str = ""  # mode family of the small-amplitude values and of ``track`` (the in-plane one)
    small_amplitude_frequencies_hz: np.ndarray = field(default_factory=lambda: np.zeros(0))
    small_amplitude_damping: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def track(self, start_s: np.ndarray, length_s: float) -> EquivalentLinearTrack:
        """Equivalent-linear truth of the windows starting at ``start_s`` (s), ``length_s`` long."""
        return equivalent_linear_track(self.truth, self.factors, self.story_drift_m, self.story_velocity_m_s,
                                       self.fs, start_s, length_s, self.drift_ref_m, self.velocity_ref_m_s,
                                       self.stiffness_nonlinear, self.damping_nonlinear, self.family)


def secant_factors(x: np.ndarray, ref: float | None, kind: str) -> np.ndarray:
    """Mean-square secant factors per column of ``x`` (samples, stories) (module doc).

    ``kind`` "stiffness": ``sum x^2 / (1 + |x|/ref) / sum x^2``; "damping": ``sum x^2 (1 + |x|/ref) /
    sum x^2``; 1 where ``ref`` is None or a column is all zero."""
    x = np.asarray(x, dtype=float)
    if ref is None:
        return np.ones(x.shape[1])
    w = x * x
    g = 1.0 / (1.0 + np.abs(x) / ref) if kind == "stiffness" else 1.0 + np.abs(x) / ref
    num, den = (w * g).sum(axis=0), w.sum(axis=0)
    return np.where(den > 0, num / np.where(den > 0, den, 1.0), 1.0)


def _family_modes(modal: Any, family: str | None) -> np.ndarray:
    """Indices of ``modal``'s modes of ``family`` (None: the in-plane family; "": every mode)."""
    if family == "" or not modal.families:
        return np.arange(modal.frequencies_hz.size)
    fam = modal.in_plane_family if family is None else family
    return np.array([j for j, f in enumerate(modal.families) if f == fam], dtype=int)


def equivalent_linear_track(truth: Any, factors: dict[str, float], drift: np.ndarray, velocity: np.ndarray,
                            fs: float, start_s: np.ndarray, length_s: float, drift_ref_m: float | None,
                            velocity_ref_m_s: float | None, stiffness_nonlinear: np.ndarray | None = None,
                            damping_nonlinear: np.ndarray | None = None,
                            family: str | None = None) -> EquivalentLinearTrack:
    """Equivalent-linear modal properties of windows of a drift / drift-velocity history (columns:
    the truth's story rows); the masks (per row, default all) say which springs / dashpots depend on
    the amplitude. ``family``: the mode family reported (None: the truth's in-plane family, "": all
    reported modes); a window's modes are the lowest of that family, so a y or torsion mode that
    crosses an x mode as the x springs soften does not shift the columns."""
    ks_on = np.ones(drift.shape[1], bool) if stiffness_nonlinear is None else np.asarray(stiffness_nonlinear)
    cs_on = np.ones(drift.shape[1], bool) if damping_nonlinear is None else np.asarray(damping_nonlinear)
    starts = np.atleast_1d(np.asarray(start_s, dtype=float))
    n = int(round(length_s * fs))
    rms, kf, cf, fr, zr = [], [], [], [], []
    fam = ""
    with single_blas_thread():
        for s in starts:
            a = int(round(s * fs))
            d, v = drift[a:a + n], velocity[a:a + n]
            if d.shape[0] < n:
                raise ValueError(f"window at {s:g} s runs past the record ({drift.shape[0] / fs:g} s)")
            k = np.where(ks_on, secant_factors(d, drift_ref_m, "stiffness"), 1.0)
            c = np.where(cs_on, secant_factors(v, velocity_ref_m_s, "damping"), 1.0)
            _, modal = truth.system(factors, k_scale=k, c_scale=c)
            sel = _family_modes(modal, family)
            fam = "" if family == "" or not modal.families else (family or modal.in_plane_family)
            rms.append(np.sqrt(np.mean(d * d, axis=0)))
            kf.append(k)
            cf.append(c)
            fr.append(modal.frequencies_hz[sel])
            zr.append(modal.damping_ratios[sel])
    m = min((f.size for f in fr), default=0)  # the same count in every window (the truth reports a fixed number)
    return EquivalentLinearTrack(starts, float(length_s), np.array(rms), np.array(kf), np.array(cf),
                                 np.array([f[:m] for f in fr]), np.array([z[:m] for z in zr]), fam)


def simulate_event(campaign: Campaign, i: int = 0) -> EventSimulation:
    """Window ``i`` of a shear-building campaign with amplitude effects, keeping the story drift
    histories: ``Campaign.window`` itself, on a copy of the campaign whose truth model also returns
    them, so the record equals ``campaign.window(i).to_window()``."""
    tm = campaign.truth_model
    if not any(e.key in AMPLITUDE_EFFECTS for e in campaign.effects):
        raise ValueError("simulate_event needs an amplitude effect (amplitude_stiffness / amplitude_damping)")
    if not isinstance(tm, BuildingTruth):
        raise ValueError(f"simulate_event needs a shear-building truth (the campaign's is {tm.kind!r})")
    rerun = dataclasses.replace(campaign, truth_model=dataclasses.replace(tm, keep_histories=True))
    sw = rerun.window(i)
    hist = sw.truth.pop(HISTORIES)
    factors = campaign.factors(i)
    with single_blas_thread():
        _, small = tm.system(factors)
    sel = _family_modes(small, None)
    ks_on, cs_on = np.asarray(hist["stiffness_nonlinear"]), np.asarray(hist["damping_nonlinear"])
    window: Window = sw.to_window()
    return EventSimulation(window=window, fs=sw.fs, story_drift_m=hist["story_drift"],
                           story_velocity_m_s=hist["story_velocity"], truth=tm, factors=factors,
                           drift_ref_m=float(hist["drift_ref_m"]) if np.any(ks_on) else None,
                           velocity_ref_m_s=float(hist["velocity_ref_m_s"]) if np.any(cs_on) else None,
                           stiffness_nonlinear=ks_on, damping_nonlinear=cs_on, event=sw.truth.get("event"),
                           family=small.in_plane_family if small.families else "",
                           small_amplitude_frequencies_hz=small.frequencies_hz[sel],
                           small_amplitude_damping=small.damping_ratios[sel])
