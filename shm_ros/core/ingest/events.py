"""Event (earthquake) detection on a window: classic STA/LTA and peak ground acceleration."""

from __future__ import annotations

import numpy as np

from shm_ros.core.ingest.config import EventDetector

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
    cs = np.vstack((np.zeros((1, x.shape[1])), np.cumsum(x * x, axis=0)))
    idx = np.arange(first, n + 1)
    lo = np.maximum(idx - nl, 0)
    sta = (cs[idx] - cs[idx - ns]) / ns
    lta = (cs[idx] - cs[lo]) / (idx - lo)[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(lta > 0, sta / lta, 0.0)
    out[first - 1:] = r
    return out


def detect_event(vals: np.ndarray, status: list[str], rate: float, detector: EventDetector, *,
                 sta_s: float, lta_s: float, sta_lta_on: float, pga_threshold: float) -> tuple[bool, float]:
    """``(is_event, pga)`` of a window ``vals`` (n, c): each usable channel minus its median (in a
    copy); PGA is the largest ``|x - median|``."""
    usable = [c for c, s in enumerate(status) if s in USABLE]
    if not usable:
        return False, 0.0
    x = vals[:, usable]
    x = np.where(np.isfinite(x), x, np.nan)
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
