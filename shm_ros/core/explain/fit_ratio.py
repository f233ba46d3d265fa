"""Does the model fit? The fit ratio of docs/interfaces.md §5, on the modal and the time path.

* Modal path: per tracked mode, the RMS frequency misfit of the calibrated model (after the accepted
  effects; the per-mode offsets are not taken out: a constant misfit is a misfit) over that mode's
  scatter, the standard deviation of its misfit's differences between successive windows whose
  amplitudes are within a factor of 2 and with no accepted step between them, divided by √2 (two
  windows' identification errors in each difference). The ratio is the largest over modes.
* Time path: the mean NRMS of the events over the mean NRMS that the pre-event noise alone gives
  (each channel's RMS before the onset over its RMS over the record).

A ratio at or above :data:`FIT_RATIO_LIMIT` says ``model_fits: false``, whatever is named.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

FIT_RATIO_LIMIT = 5.0  # a fit ratio at or above this: the model does not fit (docs/interfaces.md §5)
SCATTER_FLOOR_PCT = 0.02  # no identification resolves a frequency better than this (relative, %)
NOISE_FLOOR_PCT = 1.0  # NRMS of the noise when no record has a pre-event part to measure it on
MIN_PRE_EVENT = 50  # samples before the onset needed to measure the noise


def mode_scatter(r: np.ndarray, amplitude: np.ndarray | None = None, steps: list[int] | None = None) -> float | None:
    """One mode's scatter (%) from its misfit ``r`` (W,) in ln f: successive windows where the mode is
    found, within a factor of 2 in amplitude (when known), no step in ``steps`` (first window after a
    change) between them. None with fewer than two such pairs."""
    ok = np.flatnonzero(np.isfinite(r))
    if ok.size < 2:
        return None
    a, b = ok[:-1], ok[1:]
    keep = np.ones(a.size, bool)
    if amplitude is not None:
        amp = np.asarray(amplitude, float)
        with np.errstate(divide="ignore", invalid="ignore"):
            q = amp[b] / amp[a]
        keep &= ~np.isfinite(q) | ((q >= 0.5) & (q <= 2.0))
    for s in steps or []:
        keep &= ~((a < s) & (b >= s))
    if keep.sum() < 2:
        return None
    d = 100.0 * (r[b[keep]] - r[a[keep]])
    return float(np.std(d, ddof=1) / math.sqrt(2.0))


def modal_fit_ratio(r_after: np.ndarray, mode_numbers: list[int], amplitude: np.ndarray | None = None,
                    steps: list[int] | None = None) -> tuple[float | None, dict[str, Any]]:
    """Largest over modes of RMS misfit over scatter, and the parts: ``r_after`` (W, K) ln f_obs - ln
    f_model after the accepted effects. A mode without its own scatter takes the median of the others';
    when no mode has two pairs of windows within a factor of 2 in amplitude (a few events of different
    strength), the amplitude gate is dropped (and said so)."""
    rms, sc = [], []
    for k in range(r_after.shape[1]):
        col = r_after[:, k]
        rms.append(100.0 * float(np.sqrt(np.nanmean(col ** 2))) if np.isfinite(col).any() else math.nan)
        sc.append(mode_scatter(col, amplitude, steps))
    gated = amplitude is not None and any(s is not None for s in sc)
    if amplitude is not None and not gated:
        sc = [mode_scatter(r_after[:, k], None, steps) for k in range(r_after.shape[1])]
    known = [s for s in sc if s is not None]
    fill = float(np.median(known)) if known else None
    used = [max(s if s is not None else (fill if fill is not None else math.nan), SCATTER_FLOOR_PCT) for s in sc]
    ratios = [m / s for m, s in zip(rms, used, strict=True)]
    finite = [x for x in ratios if math.isfinite(x)]
    details: dict[str, Any] = {"path": "modes", "mode_numbers": list(mode_numbers), "rms_misfit_pct": rms,
                               "scatter_pct": used, "ratio_per_mode": ratios,
                               "amplitude_gate": bool(gated),
                               "scatter_from_other_modes": [int(m) for m, s in zip(mode_numbers, sc, strict=True)
                                                            if s is None]}
    if not finite:
        return None, details
    worst = int(np.nanargmax(np.where(np.isfinite(ratios), ratios, -np.inf)))
    details["worst_mode"] = int(mode_numbers[worst])
    return float(max(finite)), details


def pre_event_noise_nrms(outputs: np.ndarray, n_pre: int) -> float:
    """NRMS (%) that the record's pre-event noise alone would give: per channel the RMS before the
    onset over the RMS of the whole record, averaged over channels; NaN without a pre-event part."""
    if n_pre < MIN_PRE_EVENT:
        return math.nan
    y = np.asarray(outputs, float)
    pre = np.sqrt(np.nanmean(y[:n_pre] ** 2, axis=0))
    full = np.sqrt(np.nanmean(y ** 2, axis=0))
    ok = full > 0
    return float(100.0 * np.mean(pre[ok] / full[ok])) if ok.any() else math.nan


def events_fit_ratio(nrms_after: np.ndarray, noise_nrms: np.ndarray) -> tuple[float | None, dict[str, Any]]:
    """Mean NRMS after the accepted effects over the mean pre-event noise NRMS (its floor when no
    record has a pre-event part)."""
    nrms_after = np.asarray(nrms_after, float)
    noise = np.asarray(noise_nrms, float)
    measured = bool(np.isfinite(noise).any())
    level = max(float(np.nanmean(noise)) if measured else NOISE_FLOOR_PCT, 1e-6)
    details: dict[str, Any] = {"path": "events", "nrms_pct": float(np.nanmean(nrms_after)) if nrms_after.size else None,
                               "noise_nrms_pct": level, "noise_measured": measured,
                               "noise_nrms_per_event": [None if not math.isfinite(x) else float(x) for x in noise]}
    if not np.isfinite(nrms_after).any():
        return None, details
    return float(np.nanmean(nrms_after) / level), details


def combined(*parts: tuple[float | None, dict[str, Any]]) -> tuple[float | None, dict[str, Any]]:
    """Where both paths run, the larger ratio; the parts kept by path."""
    vals = [r for r, _ in parts if r is not None]
    return (max(vals) if vals else None), {d["path"]: {**d, "ratio": r} for r, d in parts}


def fit_sentence(v: dict[str, Any]) -> str:
    """Whether the model fits after the accepted effects: the fit ratio against its limit (one
    sentence, the terminal's and the report's)."""
    r = v.get("fit_ratio")
    if r is None:
        return "model fits: unknown (no fit ratio: too few windows to measure the scatter)"
    if v.get("model_fits"):
        return f"model fits: yes (fit ratio {r:.2f} < {FIT_RATIO_LIMIT:g}: the misfit left is within the scatter)"
    return (f"model fits: NO (fit ratio {r:.1f} >= {FIT_RATIO_LIMIT:g}: the misfit left is {r:.1f} times the "
            f"scatter{', whatever is named' if v['missing_physics'] else ''})")
