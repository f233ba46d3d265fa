"""Loads and ground motions: coloured, non-stationary, reproducible from a numpy ``Generator``.

* :func:`wind_loads` - spatially correlated gusts, low-pass coloured (a common and a local part),
  with a slowly wandering mean speed, so the load is neither white nor stationary.
* :func:`traffic_loads` - vehicles arriving as a Poisson process, each a moving point load with a
  bouncing dynamic part (2-4 Hz axle-hop band), shared between neighbouring load points by linear
  interpolation; the arrival rate follows the time of day.
* :func:`microtremor` - coloured ground noise for buildings (band 0.3-15 Hz).
* :func:`earthquake` - a Kanai-Tajimi filtered noise under a Saragoni-Hart envelope, scaled to a PGA.
* :func:`temperature_series` - a daily cycle plus a slow weather drift (Ornstein-Uhlenbeck).
"""

from __future__ import annotations

import numpy as np
from scipy.signal import butter, lfilter, sosfilt


def _lowpass(x: np.ndarray, fc: float, fs: float, order: int = 2) -> np.ndarray:
    sos = butter(order, min(fc / (fs / 2), 0.99), btype="low", output="sos")
    return sosfilt(sos, x, axis=0)


def _bandpass(x: np.ndarray, lo: float, hi: float, fs: float, order: int = 2) -> np.ndarray:
    sos = butter(order, [lo / (fs / 2), min(hi / (fs / 2), 0.99)], btype="band", output="sos")
    return sosfilt(sos, x, axis=0)


def wind_loads(rng: np.random.Generator, n: int, fs: float, n_points: int, rms_n: float,
               corner_hz: float = 1.5, correlation: float = 0.6, n_basis: int = 8,
               projection: np.ndarray | None = None) -> np.ndarray:
    """(n, n_points) gust forces in N; RMS about ``rms_n`` with a slowly wandering intensity.

    The spectrum is flat below ``corner_hz`` and falls as f^-2 above, plus a -20 dB white floor so
    that every mode of interest is still excited. The local part is a smooth random field: ``n_basis``
    independent gust processes along the structure, linearly interpolated to the load points.
    With ``projection`` (n_points, m) the result is ``F @ projection`` (n, m), computed without the
    dense (n, n_points) load history.
    """
    nb = max(2, min(n_basis, n_points))
    common = rng.standard_normal((n, 1))
    local = rng.standard_normal((n, nb))
    white = np.sqrt(correlation) * common + np.sqrt(1 - correlation) * local
    coloured = _lowpass(white, corner_hz, fs, order=1) * np.sqrt(fs / (np.pi * corner_hz))
    coloured += 0.1 * rng.standard_normal((n, nb))
    # interpolation weights basis -> points (rows sum to 1), renormalised to keep the variance
    xb = np.linspace(0.0, 1.0, nb)
    xp = np.linspace(0.0, 1.0, n_points)
    W = np.zeros((nb, n_points))
    for i, x in enumerate(xp):
        j = min(int(np.searchsorted(xb, x, side="right")) - 1, nb - 2)
        a = (x - xb[j]) / (xb[j + 1] - xb[j])
        W[j, i], W[j + 1, i] = 1 - a, a
    W /= np.sqrt(np.sum(W * W, axis=0, keepdims=True))
    # intensity: slow random modulation (gustiness over minutes)
    mod = _lowpass(rng.standard_normal(n), 1.0 / 120.0, fs, order=1) * np.sqrt(fs * 120.0 / np.pi)
    envelope = np.clip(1.0 + 0.35 * mod, 0.2, None)[:, None]
    Wp = W if projection is None else W @ projection
    return (rms_n / np.sqrt(1.01)) * envelope * (coloured @ Wp)


def traffic_loads(rng: np.random.Generator, n: int, fs: float, point_x: np.ndarray, length: float,
                  vehicles_per_hour: float, car_weight_n: float = 1.5e4, truck_weight_n: float = 2.5e5,
                  truck_share: float = 0.15, axle_spacing_m: float = 4.5,
                  speed_m_s: tuple[float, float] = (12.0, 25.0),
                  support_x: np.ndarray | None = None,
                  projection: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """(n, n_points) dynamic forces of vehicles crossing the deck, and the number of vehicles.

    Each vehicle (a car, or with probability ``truck_share`` a truck; lognormal weights about the
    given ones) is two axles ``axle_spacing_m`` apart, each carrying W/2 (1 + 0.1 b(t)) at constant
    speed, where b is unit band noise in 1.5-4 Hz (axle hop and body bounce). A vehicle can enter
    before the window starts, so a window never begins on an empty deck by construction.
    With ``projection`` (n_points, m) the result is ``F @ projection`` (n, m).
    """
    # load points plus the supports (a load over a support goes straight into it)
    sup = np.asarray(support_x if support_x is not None else [0.0, length], dtype=float)
    grid = np.concatenate([np.asarray(point_x, dtype=float), sup])
    order = np.argsort(grid, kind="stable")
    point_x = grid[order]
    n_load = len(grid) - sup.size
    proj = np.eye(n_load) if projection is None else np.asarray(projection, dtype=float)
    G = np.zeros((point_x.size, proj.shape[1]))  # projection on the sorted grid; supports carry 0
    G[np.argsort(order)[:n_load]] = proj
    F = np.zeros((n, proj.shape[1]))
    duration = n / fs
    n_veh = int(rng.poisson(vehicles_per_hour * (duration + 10.0) / 3600.0))
    t = np.arange(n) / fs
    bounce_sos = butter(2, [1.5 / (fs / 2), min(4.0 / (fs / 2), 0.99)], btype="band", output="sos")
    for _ in range(n_veh):
        v = rng.uniform(*speed_m_s)
        truck = rng.random() < truck_share
        w = (truck_weight_n if truck else car_weight_n) * rng.lognormal(0.0, 0.3)
        t0 = rng.uniform(-(length + axle_spacing_m) / v, duration)
        leftward = rng.random() < 0.5
        k0 = max(0, int(np.floor(t0 * fs)))
        k1 = min(n, int(np.ceil((t0 + (length + axle_spacing_m) / v) * fs)) + 1)
        if k1 <= k0:
            continue
        tt = t[k0:k1]
        bounce = sosfilt(bounce_sos, rng.standard_normal(tt.size + 64))[64:]
        bounce /= max(np.std(bounce), 1e-12)
        for lag in (0.0, axle_spacing_m):
            x = (tt - t0) * v - lag
            if leftward:
                x = length - x
            inside = (x >= 0) & (x <= length)
            p = 0.5 * w * (1.0 + 0.1 * bounce) * inside
            # share between the two load points around x (linear interpolation weights)
            j = np.clip(np.searchsorted(point_x, x) - 1, 0, point_x.size - 2)
            xa, xb = point_x[j], point_x[j + 1]
            a = np.clip((x - xa) / np.maximum(xb - xa, 1e-9), 0.0, 1.0)
            F[k0:k1] += (p * (1 - a))[:, None] * G[j] + (p * a)[:, None] * G[j + 1]
    return F, n_veh


def microtremor(rng: np.random.Generator, n: int, fs: float, rms_m_s2: float) -> np.ndarray:
    """(n,) coloured ground acceleration (band 0.3-15 Hz) with a slowly varying level."""
    x = _bandpass(rng.standard_normal(n + 256), 0.3, min(15.0, 0.45 * fs), fs)[256:]
    x /= max(np.std(x), 1e-300)
    mod = _lowpass(rng.standard_normal(n), 1.0 / 60.0, fs, order=1) * np.sqrt(fs * 60.0 / np.pi)
    return rms_m_s2 * np.clip(1.0 + 0.3 * mod, 0.2, None) * x


def kanai_tajimi(x: np.ndarray, fs: float, fg_hz: float = 2.5, zg: float = 0.6) -> np.ndarray:
    """Ground acceleration of a Kanai-Tajimi soil filter driven by ``x`` (bilinear transform)."""
    from scipy.signal import bilinear

    wg = 2 * np.pi * fg_hz
    b, a = bilinear([2 * zg * wg, wg * wg], [1.0, 2 * zg * wg, wg * wg], fs)
    return lfilter(b, a, x)


def earthquake(rng: np.random.Generator, n: int, fs: float, onset_s: float, pga_m_s2: float,
               strong_s: float = 15.0, fg_hz: float = 2.5, zg: float = 0.6) -> np.ndarray:
    """(n,) ground acceleration of one event: Kanai-Tajimi noise, Saragoni-Hart envelope, high-passed
    at 0.1 Hz (no drift), scaled so max |a| = ``pga_m_s2``."""
    t = np.arange(n) / fs - onset_s
    tau = np.clip(t, 0.0, None)
    # Saragoni-Hart type envelope peaking at 0.4 * strong_s, decaying over ~3 strong_s
    tp = 0.4 * strong_s
    env = (tau / tp) ** 2 * np.exp(2.0 * (1.0 - tau / tp))
    env[t < 0] = 0.0
    x = kanai_tajimi(rng.standard_normal(n), fs, fg_hz, zg) * env
    sos = butter(2, 0.1 / (fs / 2), btype="high", output="sos")
    x = sosfilt(sos, x)
    peak = float(np.max(np.abs(x)))
    return x * (pga_m_s2 / peak) if peak > 0 else x


def temperature_series(rng: np.random.Generator, t_s: np.ndarray, mean_c: float, daily_amplitude_c: float,
                       drift_std_c: float = 2.0, drift_days: float = 2.0, peak_hour: float = 15.0) -> np.ndarray:
    """Air temperature (deg C) at the times ``t_s`` (s since midnight UTC of day 0, ascending).

    ``mean + A sin(2 pi (t - (peak_hour - 6 h)) / 1 day) + OU drift`` with stationary std
    ``drift_std_c`` and correlation time ``drift_days``.
    """
    t_s = np.asarray(t_s, dtype=float)
    day = 86400.0
    cycle = daily_amplitude_c * np.sin(2 * np.pi * (t_s - (peak_hour - 6.0) * 3600.0) / day)
    drift = np.zeros_like(t_s)
    if t_s.size:
        tau = drift_days * day
        drift[0] = drift_std_c * rng.standard_normal()
        dts = np.diff(t_s)
        e = rng.standard_normal(max(t_s.size - 1, 0))
        for k, dt in enumerate(dts):  # exact OU update; small (one value per temperature sample)
            a = np.exp(-dt / tau)
            drift[k + 1] = a * drift[k] + drift_std_c * np.sqrt(1 - a * a) * e[k]
    return mean_c + cycle + drift


def traffic_profile(local_hour: float) -> float:
    """Relative traffic intensity over the day: quiet nights, morning and evening peaks."""
    h = local_hour
    base = 0.15 + 0.85 * np.exp(-((h - 13.0) / 6.0) ** 2)
    peaks = 0.6 * np.exp(-((h - 8.0) / 1.2) ** 2) + 0.6 * np.exp(-((h - 18.0) / 1.5) ** 2)
    return float(base + peaks)
