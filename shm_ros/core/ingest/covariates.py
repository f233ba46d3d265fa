"""Amplitude covariates of a window, carried to its modal estimate (docs/interfaces.md §3).

``rms_accel_m_s2`` says how strongly the structure was shaken in the window (amplitude-dependent
frequencies and damping are regressed on it); ``pga_m_s2`` is the peak acceleration of an event.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from shm_ros.core.types import Window

#: channel statuses whose samples say nothing about the response
_UNUSABLE = ("dropped", "dead")


def rms_accel(samples: np.ndarray, channel_names: Sequence[str], channel_status: Sequence[str] | None = None,
              input_channel: str | None = None) -> float | None:
    """RMS of the detrended accelerations, m/s^2: for each output channel (not the input channel,
    not dropped or dead), the RMS of its finite samples about their least-squares straight line
    (gravity and a slow drift removed); the median over those channels. None when no channel has
    three finite samples."""
    x = np.asarray(samples, dtype=np.float64)
    usable = [c for c, name in enumerate(channel_names)
              if name != input_channel and (channel_status is None or channel_status[c] not in _UNUSABLE)]
    if not usable or x.shape[0] < 3:
        return None
    block = x if len(usable) == x.shape[1] else x[:, usable]
    if np.isfinite(block.sum()):  # every sample finite: all channels at once
        n = x.shape[0]
        tc = np.arange(n, dtype=np.float64) - 0.5 * (n - 1)
        yc = block - block.mean(axis=0)
        # residual sum of squares about the line: sum(yc^2) - (tc . yc)^2 / (tc . tc)
        ss = np.einsum("ij,ij->j", yc, yc) - np.square(tc @ yc) / (tc @ tc)
        return float(np.median(np.sqrt(np.maximum(ss, 0.0) / n)))
    per_channel = []
    for c in usable:
        y = x[:, c]
        ok = np.isfinite(y)
        if ok.sum() < 3:
            continue
        t = np.flatnonzero(ok).astype(np.float64)
        yy = y[ok]
        tc = t - t.mean()
        slope = float(tc @ (yy - yy.mean())) / float(tc @ tc)
        resid = yy - yy.mean() - slope * tc
        per_channel.append(float(np.sqrt(np.mean(resid * resid))))
    return float(np.median(per_channel)) if per_channel else None


def window_covariates(window: Window) -> dict[str, float]:
    """Covariates of ``window`` for its modal estimate: the window's own (``rms_accel_m_s2``
    computed here when the window does not carry it, e.g. one received as a message, which has no
    covariates field) and ``pga_m_s2`` for an event or a non-zero PGA."""
    out = dict(window.covariates)
    if "rms_accel_m_s2" not in out:
        rms = rms_accel(window.samples, window.channel_names, window.channel_status, window.input_channel)
        if rms is not None:
            out["rms_accel_m_s2"] = rms
    if window.is_event or window.pga_m_s2:
        out["pga_m_s2"] = float(window.pga_m_s2)
    return out
