"""Risk of a predicted event: the probability that a story's drift ratio exceeds its limits, and
warnings when the event lies outside what the calibration saw.

The peak drift ratio of story k under the prediction is the mixture over draws of
``|N(top_d, sigma_d^2)|`` (:mod:`.predict`: each draw's peak and the error standard deviation at
its time), so

    P(peak > L) = mean_d [ Phi((top_d - L) / sigma_d) + Phi((-top_d - L) / sigma_d) ].

Warnings: the event's input PGA above the strongest calibration event's (the model error was
learnt on weaker shaking: :mod:`.model_error`), and a story whose predicted peak drift (the
draws' median) lies beyond the elastic range the model assumes (``drift_limits.elastic``): the
model's story springs are linear, the structure's are not there.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.special import ndtr  # the normal cdf

from shm_ros.core.drift_limits import DriftLimits

from .predict import EventPrediction


def exceedance(top: np.ndarray, sigma: np.ndarray, limit: float) -> float:
    """P(|N(top, sigma^2)| > limit) averaged over draws."""
    s = np.maximum(np.asarray(sigma, float), 1e-300)
    t = np.asarray(top, float)
    return float(np.mean(ndtr(-(limit - t) / s) + ndtr((-limit - t) / s)))


def event_risk(pred: EventPrediction, limits: DriftLimits | None = None,
               calibration_pga_m_s2: float | None = None) -> dict[str, Any]:
    """Per story: the predicted peak drift ratio (median, 95 % interval) and the exceedance
    probability of each limit; the warnings (module doc). ``calibration_pga_m_s2``: the strongest
    calibration event's input PGA (default: the one the model error was learnt with, if any)."""
    lim = limits or DriftLimits()
    if calibration_pga_m_s2 is None and pred.model_error is not None:
        calibration_pga_m_s2 = pred.model_error.get("calibration_pga_max_m_s2")
    stories: list[dict[str, Any]] = []
    warnings: list[str] = []
    for c in pred.channels:
        if c.quantity != "drift_ratio" or not c.peak_top.size:
            continue
        k = int(c.name.removeprefix("drift_ratio"))
        peak = float(np.median(c.peak_top))
        row = {"story": k, "peak_drift_ratio": peak, "peak_ci95": [float(c.peak_ci[0]), float(c.peak_ci[1])],
               "exceedance": [{"limit": L, "probability": exceedance(c.peak_top, c.peak_sigma, L)}
                              for L in lim.for_story(k)]}
        stories.append(row)
    beyond = [(int(r["story"]), float(r["peak_drift_ratio"])) for r in stories
              if float(r["peak_drift_ratio"]) > lim.elastic]
    if beyond:
        k, peak = max(beyond, key=lambda x: x[1])
        warnings.append(f"predicted peak drift ratio beyond the elastic range the model assumes ({lim.elastic:g}) "
                        f"in {len(beyond)} stor{'y' if len(beyond) == 1 else 'ies'} (largest {peak:.4f}, story {k}): "
                        "the prediction is linear, the structure is not")
    if calibration_pga_m_s2 is None:
        pga_note = "calibration PGA unknown (no calibration events given): not compared"
    else:
        pga_note = None
        if pred.input_pga_m_s2 > calibration_pga_m_s2:
            warnings.append(f"input PGA {pred.input_pga_m_s2:.3g} m/s^2 above the strongest calibration event's "
                            f"({calibration_pga_m_s2:.3g} m/s^2): outside what the calibration saw")
    out: dict[str, Any] = {"limits": lim.to_dict(), "limits_from": "structure file" if lim.given else "defaults",
                           "input_pga_m_s2": pred.input_pga_m_s2, "calibration_pga_max_m_s2": calibration_pga_m_s2,
                           "stories": stories, "warnings": warnings, "outside_calibration": bool(warnings)}
    if pga_note:
        out["note"] = pga_note
    return out
