"""The physics of a dense campaign, one function per kind: per-window states and the truth record.

Each returns a :class:`DenseTruth`: the stiffness factor per window (and, for girders, bearing
stiffnesses per window), added damping per window, what was done, and the expected answer.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .drivers import ar1, first_order_lag, humidity, random_walk, solar_gradient, to_peak_to_peak
from .thermal import ThermalLaw


@dataclass
class Weather:
    t_h: np.ndarray
    air_c: np.ndarray
    amplitude: np.ndarray          # rms acceleration of the window, m/s^2 (traffic, wind)


@dataclass
class DenseTruth:
    e_factor: np.ndarray
    expected: str
    acceptable: tuple[str, ...] = ()
    k_vertical: np.ndarray | None = None   # (W, 4) girders only
    k_rotation: np.ndarray | None = None
    added_damping: np.ndarray | None = None
    record: dict = field(default_factory=dict)
    change_window: int | None = None


def lagged_temperature(rng: np.random.Generator, wx: Weather, structure: str) -> DenseTruth:
    law = ThermalLaw.draw(rng)
    tau = float(rng.uniform(3.0, 12.0))
    grad = solar_gradient(wx.t_h, float(rng.uniform(1.0, 4.0)), float(rng.uniform(0.5, 2.0)))
    t_struct = first_order_lag(wx.air_c, 1.0, tau) + grad
    return DenseTruth(e_factor=law.factor(t_struct), expected="temperature_dependent_stiffness",
                      record={"law": law.__dict__, "lag_hours": tau, "structure_temperature_c": t_struct})


def humidity_stiffness(rng: np.random.Generator, wx: Weather, structure: str) -> DenseTruth:
    rh = humidity(rng, wx.t_h, wx.air_c)
    tau = float(rng.uniform(24.0, 72.0))
    moist = first_order_lag(rh, 1.0, tau)
    ptp = float(rng.uniform(0.02, 0.04))
    e = 1.0 - to_peak_to_peak(moist, ptp)             # wetter -> heavier and softer in effect
    return DenseTruth(e_factor=e, expected="unexplained_structure",
                      record={"lag_hours": tau, "stiffness_peak_to_peak": ptp, "relative_humidity_pct": rh})


def stick_slip(rng: np.random.Generator, wx: Weather, structure: str, k_v: np.ndarray) -> DenseTruth:
    """Friction bearings, equivalent-linear per window: stuck (rotational stiffness k_stick) below the
    slip rotation theta_s = mu(T) N r / k_stick, secant k_stick theta_s / theta above, with friction
    damping
    mu rises in the cold. The bearing rotation grows with the window's vibration amplitude."""
    w = wx.t_h.size
    k_stick = float(rng.uniform(2e9, 6e9))
    mu = 0.03 + 0.02 / (1.0 + np.exp((wx.air_c - 0.0) / 3.0))            # PTFE: higher when cold
    theta_s = mu / mu.mean() * float(np.median(wx.amplitude)) * float(rng.uniform(1.0, 2.0))
    theta = wx.amplitude                                                    # rotation ~ amplitude (scaled)
    ratio = np.clip(theta_s / theta, 0.0, 1.0)
    k_rot = k_stick * ratio
    loss = (4.0 / np.pi) * ratio * (1.0 - ratio)                            # Coulomb: energy / (pi k x^2)
    k_rotation = np.zeros((w, 4))
    k_rotation[:, :] = k_rot[:, None]
    return DenseTruth(e_factor=np.ones(w), expected="amplitude_dependent_stiffness",
                      acceptable=("support_flexibility",), k_vertical=np.tile(k_v, (w, 1)), k_rotation=k_rotation,
                      added_damping=0.01 * loss,
                      record={"k_stick_N_m_rad": k_stick, "friction_coefficient": mu, "stuck_fraction": ratio})


def settlement(rng: np.random.Generator, wx: Weather, structure: str, k_v: np.ndarray) -> DenseTruth:
    w = wx.t_h.size
    at = int(rng.integers(int(0.4 * w), int(0.7 * w)))
    bearing = int(rng.choice([1, 2]))
    loss = float(rng.uniform(0.8, 0.95))
    kv = np.tile(k_v, (w, 1))
    kv[at:, bearing] *= 1.0 - loss
    return DenseTruth(e_factor=np.ones(w), expected="stiffness_change_at_time", acceptable=("support_flexibility",),
                      k_vertical=kv, k_rotation=np.zeros((w, 4)), change_window=at,
                      record={"bearing": bearing, "vertical_stiffness_loss": loss})


def ar1_null(rng: np.random.Generator, wx: Weather, structure: str) -> DenseTruth:
    rho, ptp = float(rng.uniform(0.9, 0.995)), float(rng.uniform(0.005, 0.03))
    x = to_peak_to_peak(ar1(rng, wx.t_h.size, rho), ptp)
    return DenseTruth(e_factor=1.0 + x, expected="none", record={"rho": rho, "peak_to_peak": ptp, "driver": x})


def random_walk_null(rng: np.random.Generator, wx: Weather, structure: str) -> DenseTruth:
    ptp = float(rng.uniform(0.005, 0.03))
    x = to_peak_to_peak(random_walk(rng, wx.t_h.size), ptp)
    return DenseTruth(e_factor=1.0 + x, expected="none", record={"peak_to_peak": ptp, "driver": x})


def clean(rng: np.random.Generator, wx: Weather, structure: str) -> DenseTruth:
    return DenseTruth(e_factor=np.ones(wx.t_h.size), expected="none")


GIRDER_ONLY = {"dense_stick_slip": stick_slip, "dense_settlement": settlement}
ANY = {"dense_lagged_temperature": lagged_temperature, "dense_humidity": humidity_stiffness,
       "dense_ar1_null": ar1_null, "dense_random_walk_null": random_walk_null, "dense_clean": clean}
