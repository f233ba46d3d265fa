"""Time-resolved truth of an event: equivalent-linear modal properties of moving windows.

During an earthquake the softening story springs ``f = k d / (1 + |d| / d_ref)`` of
:mod:`shm_ros.core.simulate.newmark` make the modes move within the record. The truth of one
window ``[a, b)`` of the response is the linear model whose story ``i`` has the *mean-square
secant stiffness* of that window's drift history

    k_eq,i = sum_t d_i(t) f_i(d_i(t)) / sum_t d_i(t)^2
           = k_i sum_t d_i^2 / (1 + |d_i| / d_ref) / sum_t d_i^2

(the least-squares straight line through the window's force-drift points; the same linearisation
for amplitude-dependent story dashpots with the drift velocity). For a Gaussian drift it equals the
window factor of the simulator (``E[g'(d)]``, Stein's lemma), but it needs no Gaussian or stationary
response: a window that straddles the strong shaking and the quiet before it, or a free decay, has
the stiffness its samples actually carry, weighted by their squared amplitude as a least-squares
identification weights them. The frequencies and damping ratios are those of the truth model's
state space with these stiffness and damping factors (:meth:`BuildingTruth.system`).

:func:`simulate_event` reruns window ``i`` of a campaign exactly as the campaign does (same draws of
loads and sensor noise) and keeps the story drift histories.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shm_ros.core.simulate.campaign import AMPLITUDE_EFFECTS, Campaign, rng_for, single_blas_thread
from shm_ros.core.simulate.newmark import simulate_building_nonlinear
from shm_ros.core.types import Window

__all__ = ["EquivalentLinearTrack", "EventSimulation", "secant_factors", "equivalent_linear_track",
           "simulate_event", "warm_up_samples"]


@dataclass
class EquivalentLinearTrack:
    """Equivalent-linear truth of windows ``[start_s, start_s + length_s)`` of an event record."""

    start_s: np.ndarray  # (w,) window starts, s from the record start
    length_s: float
    story_drift_rms_m: np.ndarray  # (w, n_stories)
    stiffness_factor: np.ndarray  # (w, n_stories) k_eq / k
    damping_factor: np.ndarray  # (w, n_stories) c_eq / c
    frequencies_hz: np.ndarray  # (w, n_modes)
    damping_ratios: np.ndarray  # (w, n_modes)

    @property
    def centre_s(self) -> np.ndarray:
        return self.start_s + 0.5 * self.length_s


@dataclass
class EventSimulation:
    """One simulated event window with what the truth needs to follow it in time."""

    window: Window  # what the sensors recorded (as ``SimulatedWindow.to_window``)
    fs: float
    story_drift_m: np.ndarray  # (n, n_stories) after warm-up
    story_velocity_m_s: np.ndarray  # (n, n_stories)
    truth: Any  # the campaign's truth model (``BuildingTruth``)
    factors: dict[str, float]
    drift_ref_m: float | None  # None: linear story springs
    velocity_ref_m_s: float | None  # None: linear story dashpots
    stiffness_nonlinear: np.ndarray  # (n_stories,) bool: softening spring (a foundation's stays linear)
    damping_nonlinear: np.ndarray  # (n_stories,) bool
    event: dict[str, float] | None
    small_amplitude_frequencies_hz: np.ndarray = field(default_factory=lambda: np.zeros(0))
    small_amplitude_damping: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def track(self, start_s: np.ndarray, length_s: float) -> EquivalentLinearTrack:
        """Equivalent-linear truth of the windows starting at ``start_s`` (s), ``length_s`` long."""
        return equivalent_linear_track(self.truth, self.factors, self.story_drift_m, self.story_velocity_m_s,
                                       self.fs, start_s, length_s, self.drift_ref_m, self.velocity_ref_m_s,
                                       self.stiffness_nonlinear, self.damping_nonlinear)


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


def equivalent_linear_track(truth: Any, factors: dict[str, float], drift: np.ndarray, velocity: np.ndarray,
                            fs: float, start_s: np.ndarray, length_s: float, drift_ref_m: float | None,
                            velocity_ref_m_s: float | None, stiffness_nonlinear: np.ndarray | None = None,
                            damping_nonlinear: np.ndarray | None = None) -> EquivalentLinearTrack:
    """Equivalent-linear modal properties of windows of a drift / drift-velocity history; the masks
    (per story, default all) say which springs / dashpots depend on the amplitude."""
    ks_on = np.ones(drift.shape[1], bool) if stiffness_nonlinear is None else np.asarray(stiffness_nonlinear)
    cs_on = np.ones(drift.shape[1], bool) if damping_nonlinear is None else np.asarray(damping_nonlinear)
    starts = np.atleast_1d(np.asarray(start_s, dtype=float))
    n = int(round(length_s * fs))
    rms, kf, cf, fr, zr = [], [], [], [], []
    for s in starts:
        a = int(round(s * fs))
        d, v = drift[a:a + n], velocity[a:a + n]
        if d.shape[0] < n:
            raise ValueError(f"window at {s:g} s runs past the record ({drift.shape[0] / fs:g} s)")
        k = np.where(ks_on, secant_factors(d, drift_ref_m, "stiffness"), 1.0)
        c = np.where(cs_on, secant_factors(v, velocity_ref_m_s, "damping"), 1.0)
        _, modal = truth.system(factors, k_scale=k, c_scale=c)
        rms.append(np.sqrt(np.mean(d * d, axis=0)))
        kf.append(k)
        cf.append(c)
        fr.append(modal.frequencies_hz)
        zr.append(modal.damping_ratios)
    return EquivalentLinearTrack(starts, float(length_s), np.array(rms), np.array(kf), np.array(cf),
                                 np.array(fr), np.array(zr))


def warm_up_samples(campaign: Campaign, system: Any) -> int:
    """Warm-up samples the campaign simulates before a window (5 time constants of the slowest
    mode, 10 to 120 s), the same rule as ``Campaign.window``."""
    slow = float(np.min(-system.poles.real[system.conjugate])) if np.any(system.conjugate) else 1.0
    return int(round(min(120.0, max(10.0, 5.0 / slow)) * campaign.scenario.fs))


def simulate_event(campaign: Campaign, i: int = 0) -> EventSimulation:
    """Window ``i`` of a shear-building campaign with amplitude effects, keeping the drift
    histories: the recorded samples equal ``campaign.window(i).to_window().samples`` (no faults)."""
    sc, tm = campaign.scenario, campaign.truth_model
    amp = [e for e in campaign.effects if e.key in AMPLITUDE_EFFECTS]
    if not amp:
        raise ValueError("simulate_event needs an amplitude effect (amplitude_stiffness / amplitude_damping)")
    with single_blas_thread():
        cond, factors = campaign.conditions(i), campaign.factors(i)
        n = int(round(sc.window_s * sc.fs))
        system, small = tm.system(factors)
        n_warm = warm_up_samples(campaign, system)
        u, event = tm.loads(rng_for(sc.seed, 3, i), n_warm + n, cond, sc, system, campaign.earthquakes.get(i))
        y, eq = simulate_building_nonlinear(tm, factors, amp, u, 1.0 / sc.fs, n_warm)
        accel = np.ascontiguousarray(y[n_warm:])
        nrng = rng_for(sc.seed, 4, i)
        values = np.column_stack([s.measure(nrng, accel[:, c]) for c, s in enumerate(campaign.sensors)])
    start, _ = campaign.window_bounds_ns(i)
    window = Window(window_id=f"w{i:05d}", start_ns=start, sample_rate_hz=sc.fs,
                    channel_names=campaign.sensor_ids, samples=values,
                    temperature_c=campaign.measured_temperature(i), is_event=event is not None,
                    pga_m_s2=float((event or {}).get("pga_m_s2", 0.0)),
                    input_channel=tm.nominal.input_sensor)
    return EventSimulation(window=window, fs=sc.fs, story_drift_m=eq["story_drift"],
                           story_velocity_m_s=eq["story_velocity"], truth=tm, factors=factors,
                           drift_ref_m=eq["drift_ref_m"] if np.any(eq["stiffness_nonlinear"]) else None,
                           velocity_ref_m_s=eq["velocity_ref_m_s"] if np.any(eq["damping_nonlinear"]) else None,
                           stiffness_nonlinear=eq["stiffness_nonlinear"], damping_nonlinear=eq["damping_nonlinear"],
                           event=event, small_amplitude_frequencies_hz=small.frequencies_hz,
                           small_amplitude_damping=small.damping_ratios)
