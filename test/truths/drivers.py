"""Environmental and unmeasured drivers of a dense (hourly) campaign.

* Air temperature: seasonal cycle + daily cycle (peak at 15 h) + weather (AR(1), 0.97 per hour).
* Structure temperature: the air's through a first-order lag (time constant hours) plus a gradient
  offset (sun on the deck: a daily bump) — so the structure's temperature is not the sensor's.
* Relative humidity: anti-correlated daily cycle, weather and rain spells
the structure's moisture
  follows through a lag of a day or more. Humidity is never written to the table.
* Slow unmeasured drivers (the nulls): AR(1) with rho 0.9-0.995 per window and random walks,
  scaled to a peak-to-peak amplitude.
"""

from __future__ import annotations

import numpy as np


def ar1(rng: np.random.Generator, n: int, rho: float, sd: float = 1.0) -> np.ndarray:
    """Stationary AR(1): x[k] = rho x[k-1] + e[k], marginal standard deviation ``sd``."""
    e = rng.standard_normal(n) * sd * np.sqrt(1.0 - rho**2)
    x = np.empty(n)
    x[0] = sd * rng.standard_normal()
    for k in range(1, n):
        x[k] = rho * x[k - 1] + e[k]
    return x


def random_walk(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.cumsum(rng.standard_normal(n))


def to_peak_to_peak(x: np.ndarray, ptp: float) -> np.ndarray:
    """Centre ``x`` and scale it to the given peak-to-peak amplitude."""
    x = x - x.mean()
    return x * (ptp / max(np.ptp(x), 1e-300))


def first_order_lag(x: np.ndarray, dt_h: float, tau_h: float) -> np.ndarray:
    """y' = (x - y) / tau, exact for x constant over a step
    starts in equilibrium with x[0]."""
    a = np.exp(-dt_h / tau_h)
    y = np.empty_like(x)
    y[0] = x[0]
    for k in range(1, x.size):
        y[k] = a * y[k - 1] + (1 - a) * x[k]
    return y


def air_temperature(rng: np.random.Generator, t_h: np.ndarray, start_doy: float, mean_c: float,
                    season_amp: float, daily_amp: float, weather_sd: float) -> np.ndarray:
    doy = start_doy + t_h / 24.0
    seasonal = mean_c - season_amp * np.cos(2 * np.pi * (doy - 15.0) / 365.25)   # coldest mid-January
    daily = daily_amp * np.cos(2 * np.pi * ((t_h % 24.0) - 15.0) / 24.0)
    return seasonal + daily + ar1(rng, t_h.size, 0.97, weather_sd)


def solar_gradient(t_h: np.ndarray, amp_c: float, offset_c: float) -> np.ndarray:
    """Structure minus (lagged) air temperature: a constant part and a daytime bump (sun 9-17 h)."""
    hour = t_h % 24.0
    bump = np.clip(np.sin(np.pi * (hour - 9.0) / 8.0), 0.0, None)
    return offset_c + amp_c * bump


def humidity(rng: np.random.Generator, t_h: np.ndarray, air_c: np.ndarray) -> np.ndarray:
    """Relative humidity (%): high at night, weather, rain spells
    clipped to 20-100 %."""
    rh = 75.0 - 1.5 * (air_c - air_c.mean()) + ar1(rng, t_h.size, 0.98, 8.0)
    rain = np.zeros(t_h.size)
    for start in rng.choice(t_h.size, size=max(1, t_h.size // 150), replace=False):
        rain[start: start + int(rng.integers(6, 36))] = 20.0
    return np.clip(rh + rain, 20.0, 100.0)
