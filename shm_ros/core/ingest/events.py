"""Event (earthquake) detection on a window: classic STA/LTA and peak ground acceleration.

A triggered window is called by its name (:func:`event_kind`): an **earthquake** when the ground
or input channel itself has a PGA of at least ``earthquake_pga_m_s2`` (0.05 m/s^2) and its own
STA/LTA trigger fires; every other triggered window is a **high-amplitude window** (traffic, wind,
works: the structure shakes, the ground does not).
"""

from __future__ import annotations

import enum

import numpy as np

from shm_ros.core.ingest.config import EventDetector, IngestConfig
from shm_ros.core.types import Window

#: Channel statuses whose samples the detectors look at.
USABLE = ("ok", "noisy", "clipped")


def sta_lta(x: np.ndarray, rate: float, sta_s: float, lta_s: float) -> np.ndarray:
    """Classic STA/LTA of ``x`` (n,) or (n, c): trailing means of x^2 over ``sta_s`` and ``lta_s``.

    While fewer than ``lta_s`` seconds precede a sample the LTA is the mean over all of them (at
    least ``2 * sta_s``; zeros before), so that a record that starts shortly before an earthquake
    still triggers. Written out because it is a few lines of cumulative sums.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    ns, nl = max(1, int(round(sta_s * rate))), max(1, int(round(lta_s * rate)))
    n = x.shape[0]
    out = np.zeros_like(x)
    first = min(nl, 2 * ns)
    if n < first:
        return out
    cs = np.empty((n + 1, x.shape[1]))
    cs[0] = 0.0
    np.cumsum(x * x, axis=0, out=cs[1:])
    # rows idx = first..n of cs, less the rows idx - ns and max(idx - nl, 0): slices of cs
    idx = np.arange(first, n + 1)
    lo = np.maximum(idx - nl, 0)
    top = cs[first:]
    sta = out[first - 1:]  # computed in place (no temporaries of the window's size)
    np.subtract(top, cs[first - ns: n + 1 - ns], out=sta)
    sta /= ns
    lta = top.copy()  # less cs[0] = 0 while idx < nl
    j0 = max(first, nl)
    if j0 <= n:
        lta[j0 - first:] -= cs[j0 - nl: n + 1 - nl]
    lta /= (idx - lo)[:, None]
    positive = lta > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        sta /= lta
    sta[~positive] = 0.0
    return out


def detect_event(vals: np.ndarray, status: list[str], rate: float, detector: EventDetector, *,
                 sta_s: float, lta_s: float, sta_lta_on: float, pga_threshold: float) -> tuple[bool, float]:
    """``(is_event, pga)`` of a window ``vals`` (n, c): each usable channel minus its median (in a
    copy); PGA is the largest ``|x - median|``."""
    usable = [c for c, s in enumerate(status) if s in USABLE]
    if not usable:
        return False, 0.0
    x = vals[:, usable]
    finite = np.isfinite(x)
    if finite.all():  # (the common case: np.median is much faster than np.nanmedian along an axis)
        x = x - np.median(x, axis=0)
    else:
        x = np.where(finite, x, np.nan)
        x = x - np.nanmedian(x, axis=0)
        x = np.nan_to_num(x, nan=0.0)
    pga = float(np.abs(x).max()) if x.size else 0.0
    trig_pga = pga >= pga_threshold
    trig_sl = False
    if detector in (EventDetector.STA_LTA, EventDetector.EITHER, EventDetector.BOTH):
        trig_sl = float(sta_lta(x, rate, sta_s, lta_s).max(initial=0.0)) >= sta_lta_on
    trigger = {EventDetector.STA_LTA: trig_sl, EventDetector.PGA: trig_pga,
               EventDetector.EITHER: trig_sl or trig_pga, EventDetector.BOTH: trig_sl and trig_pga}
    return trigger.get(detector, False), pga


class EventKind(enum.StrEnum):
    """What a window is called (``Window.event_kind``)."""

    NONE = "none"  # not triggered
    EARTHQUAKE = "earthquake"  # the ground / input channel shook (PGA and STA/LTA on it)
    HIGH_AMPLITUDE = "high_amplitude"  # triggered, not on the ground: traffic, wind, works


def event_kind(vals: np.ndarray, names: list[str], status: list[str] | None, rate: float, input_channel: str | None,
               is_event: bool, *, sta_s: float, lta_s: float, sta_lta_on: float,
               earthquake_pga_m_s2: float) -> tuple[EventKind, float]:
    """``(kind, input PGA)`` of a window (module doc); the input PGA is 0 without a usable input channel."""
    if input_channel is None or input_channel not in names:
        return (EventKind.HIGH_AMPLITUDE if is_event else EventKind.NONE), 0.0
    c = names.index(input_channel)
    if status is not None and status[c] not in USABLE:
        return (EventKind.HIGH_AMPLITUDE if is_event else EventKind.NONE), 0.0
    x = np.asarray(vals[:, c], dtype=float)
    x = np.nan_to_num(x - np.nanmedian(x), nan=0.0) if np.isfinite(x).any() else np.zeros_like(x)
    pga = float(np.abs(x).max()) if x.size else 0.0
    fired = float(sta_lta(x, rate, sta_s, lta_s).max(initial=0.0)) >= sta_lta_on
    if pga >= earthquake_pga_m_s2 and fired:
        return EventKind.EARTHQUAKE, pga
    return (EventKind.HIGH_AMPLITUDE if is_event else EventKind.NONE), pga


def window_event_kind(window: Window, config: IngestConfig | None = None) -> EventKind:
    """:func:`event_kind` of a window (its ``is_event`` flag, input channel and samples) under
    ``config`` (default: the ingest defaults); for windows read from files or messages that do not
    carry the kind."""
    cfg = config or IngestConfig()
    kind, _ = event_kind(window.samples, list(window.channel_names), window.channel_status, window.sample_rate_hz,
                         window.input_channel, bool(window.is_event), sta_s=cfg.sta_s, lta_s=cfg.lta_s,
                         sta_lta_on=cfg.sta_lta_on, earthquake_pga_m_s2=cfg.earthquake_pga_m_s2)
    return kind
