"""Helpers shared by candidate files: covariates of the context, hour of the day, windows by hints."""

from __future__ import annotations

import numpy as np

from .base import Context


def covariate(context: Context, name: str) -> np.ndarray:
    """(W,) covariate with missing values filled by linear interpolation (zeros if it is absent)."""
    return fill_missing(context.covariates.get(name, np.zeros(len(context.times_s))))


def temperatures(context: Context) -> tuple[np.ndarray, float]:
    """(W,) air temperatures (``temperature_c``), missing ones interpolated between their neighbours
    (temperature is smooth in time; a median in their place would put a frosty night's window at the
    average state), and the reference: the median of the measured ones (0 when none is)."""
    t = np.asarray(context.covariates.get("temperature_c", np.full(len(context.times_s), np.nan)), dtype=float)
    ref = float(np.nanmedian(t)) if np.isfinite(t).any() else 0.0
    return (fill_missing(t) if np.isfinite(t).any() else np.full(t.shape, ref)), ref


def fill_missing(x: np.ndarray) -> np.ndarray:
    """Missing values (NaN) by linear interpolation (the nearest value at the ends; zeros if all miss)."""
    x = np.asarray(x, float).copy()
    bad = ~np.isfinite(x)
    if bad.all():
        return np.zeros_like(x)
    if bad.any():
        i = np.arange(x.size)
        x[bad] = np.interp(i[bad], i[~bad], x[~bad])
    return x


def amplitude(context: Context) -> tuple[str, np.ndarray]:
    """The amplitude covariate the hints name, else rms_accel_m_s2, else pga_m_s2."""
    name = str(context.hints.get("covariate", ""))
    if name not in ("rms_accel_m_s2", "pga_m_s2"):
        name = "rms_accel_m_s2" if "rms_accel_m_s2" in context.covariates else "pga_m_s2"
    return name, covariate(context, name)


def hour_utc(context: Context) -> np.ndarray:
    return ((context.start_epoch_s + np.asarray(context.times_s, float)) % 86400.0) / 3600.0


def daily_windows(hour: np.ndarray, windows) -> np.ndarray:
    """(W,) bool: the hour of the day (UTC) inside any of ``windows``, each ``[start, end)`` in hours
    (wrapping past midnight when end < start). ``windows`` may also be one ``[start, end]`` pair."""
    w = np.asarray(windows, float).reshape(-1, 2)
    h = np.asarray(hour, float)[:, None]
    return np.any(((h - w[:, 0]) % 24.0) < ((w[:, 1] - w[:, 0]) % 24.0), axis=1)


def hours_text(windows) -> str:
    """``windows`` of :func:`daily_windows` in words: "between 7 and 9.5 h and between 17 and 19.5 h"."""
    return " and ".join(f"between {a:g} and {b:g} h" for a, b in np.asarray(windows, float).reshape(-1, 2))


def after_change(context: Context) -> np.ndarray:
    """(W,) 1.0 from locate's hinted change window (``change_index``) on, 0.0 before."""
    return (np.arange(len(context.times_s)) >= int(context.hints["change_index"])).astype(float)


def change_time(context: Context) -> float:
    """Seconds since the first window of locate's hinted change window."""
    return float(context.times_s[int(context.hints["change_index"])])


def hinted_time_span(context: Context) -> tuple[float, float]:
    """Seconds since the first window within which locate placed the hinted change: the times of the
    ends of ``change_span`` (a change inside held-out windows: those windows), else the change window's
    (:meth:`.base.Candidate.time_span` of a candidate that starts at the hinted window itself)."""
    i = int(context.hints["change_index"])
    a, b = context.hints.get("change_span", (i, i))
    t = np.asarray(context.times_s, float)
    ends = [t[min(max(int(k), 0), t.size - 1)] for k in (a, b, i)]
    return float(min(ends)), float(max(ends))


def hinted_window_look_elsewhere(context: Context) -> float:
    """The look-elsewhere correction of a candidate that starts at locate's hinted change window
    itself (``change_index``; a change inside held-out windows: ``change_span``) instead of searching
    for it: ln(full range / hinted range) in windows, the full range being the windows a change can
    start at (the 2nd to the second-to-last, as the step's prior), the hinted range the hinted span.
    Locate searched every window of the same data for it, which the hinted fit must not get for free.
    0 without a hint."""
    h, W = context.hints, len(context.times_s)
    if "change_index" not in h or W <= 3:
        return 0.0
    i = int(h["change_index"])
    a, b = h.get("change_span", (i, i))
    return float(max(np.log((W - 2) / max(int(b) - int(a) + 1, 1)), 0.0))
