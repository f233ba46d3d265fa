"""Identification of short windows of one pre-processed event record, and the matching of the modes
each window finds to a set of reference modes."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from shm_ros.core.identify import IdentifyConfig, identify_array
from shm_ros.core.modal import mac_matrix
from shm_ros.core.preprocess import Prepared
from shm_ros.core.stabilization import StabilityConfig

__all__ = ["WindowModes", "ReferenceMode", "identify_segment", "match_modes", "MOVING_STABILITY", "PHASE_STABILITY"]

# A short window of a structure whose stiffness changes inside it is not shift-invariant enough for
# the forward/backward (two-A) agreement within 1 % or a 5 % damping stability: on the simulated
# softening building under PGA 1.5 m/s^2, 10-period windows found the fundamental mode in 40-50 % of
# the windows with the defaults and in 75-80 % with these, at the same median error (0.2-0.4 % from
# the equivalent-linear truth).
MOVING_STABILITY = StabilityConfig(freq_tol=0.02, damping_tol=0.3, mac_min=0.95, two_a=False)
# A whole phase keeps the defaults but for a 20 % damping stability: in quiet pre-event records the
# weakly excited first mode's damping wanders by more than 5 % between orders (one of 12 simulated
# records lost mode 1 before the event with the defaults).
PHASE_STABILITY = StabilityConfig(damping_tol=0.2)


@dataclass
class WindowModes:
    """The modes one window found (ascending frequency; shapes complex, unit norm, over the outputs)."""

    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    frequency_spread_hz: np.ndarray
    shapes: np.ndarray  # (n_modes, n_outputs)
    method: str


@dataclass
class ReferenceMode:
    frequency_hz: float
    damping_ratio: float
    shape: np.ndarray  # (n_outputs,) complex or real


def identify_segment(prep: Prepared, a: int, b: int, cfg: IdentifyConfig, input_channel: str | None
                     ) -> WindowModes | None:
    """Modes of samples ``[a, b)`` of ``prep`` (None when the window is too short or singular)."""
    part = Prepared(prep.data[a:b], prep.sample_rate_hz, prep.channel_names)
    try:
        res = identify_array(part, cfg, input_channel=input_channel)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError):
        return None
    picked = res.diagram.picked
    n_out = len(res.channel_names)
    return WindowModes(np.array([p.frequency_hz for p in picked]), np.array([p.damping_ratio for p in picked]),
                       np.array([p.frequency_spread_hz for p in picked]),
                       (np.array([p.mode_shape_complex for p in picked]) if picked else np.zeros((0, n_out))),
                       res.estimate.method)


def match_modes(found: WindowModes, refs: list[ReferenceMode], max_drop: float, mac_min: float,
                max_rise: float = 0.25) -> list[int | None]:
    """For every reference, the index of the found mode that matches it (or None).

    A found mode is a candidate for a reference when its frequency lies within
    ``[(1 - max_drop) f_ref, (1 + max_rise) f_ref]`` and its MAC with the reference shape is at least
    ``mac_min``; candidates are assigned greedily by ``|ln(f / f_ref)| + (1 - MAC)``, each found mode
    to at most one reference.
    """
    out: list[int | None] = [None] * len(refs)
    if found.frequency_hz.size == 0 or not refs:
        return out
    ref_shapes = np.array([r.shape for r in refs])
    mac = mac_matrix(ref_shapes, found.shapes)  # (refs, found)
    fr = np.array([r.frequency_hz for r in refs])
    ratio = found.frequency_hz[None, :] / fr[:, None]
    ok = (ratio >= 1 - max_drop) & (ratio <= 1 + max_rise) & (mac >= mac_min)
    score = np.where(ok, np.abs(np.log(ratio)) + (1 - mac), np.inf)
    for _ in range(len(refs)):
        r, j = np.unravel_index(int(np.argmin(score)), score.shape)
        if not np.isfinite(score[r, j]):
            break
        out[int(r)] = int(j)
        score[r, :] = np.inf
        score[:, j] = np.inf
    return out


def moving_config(base: IdentifyConfig, max_order: int, block_rows: int) -> IdentifyConfig:
    """The identification settings of a moving window."""
    return replace(base, max_order=max_order, block_rows=block_rows, uncertainty=False,
                   stability=MOVING_STABILITY)
