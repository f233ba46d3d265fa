"""A second look at a setup for a mode the other setups found.

Automatic picking needs a mode's poles to be stable at enough model orders; in a short setup a mode
can miss that and the merged shape then lacks that setup's points. With the merged mode known (its
frequency and its shape over the references), the setup's own stabilization diagram is searched for
it: poles that are stable (frequency, damping and shape between orders) and physical, within
``freq_tol`` of the merged frequency, whose reference components have MAC >= ``mac_min`` with the
merged ones. Found at >= ``min_poles`` orders, the mode is added to that setup's estimate (the
median-frequency pole's shape, made real) and the setups are merged again; the mode's note says so.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from shm_ros.core.identify import IdentificationResult
from shm_ros.core.modal import mac
from shm_ros.core.roving.merge_post import GlobalMode
from shm_ros.core.stabilization import real_mode_shape
from shm_ros.core.types import Mode

__all__ = ["second_look"]


def second_look(results: Sequence[IdentificationResult], modes: Sequence[GlobalMode], references: Sequence[str],
                freq_tol: float = 0.01, mac_min: float = 0.9, min_poles: int = 3) -> int:
    """Add to each setup's estimate the merged modes it missed where its diagram holds them; returns
    how many were added."""
    added = 0
    for g in modes:
        g_ref = np.array([g.shape.get(r, np.nan) for r in references])
        for k in g.missing_setups:
            res = results[k - 1]
            poles, flags = res.diagram.poles, res.diagram.flags
            names = res.estimate.sensor_ids
            idx = [names.index(r) for r in references]
            ok = flags.stable & flags.physical_ok & (np.abs(poles.frequency_hz / g.frequency_hz - 1) <= freq_tol)
            cand = np.flatnonzero(ok)
            if cand.size:
                shapes = np.array([real_mode_shape(poles.shape[j]) for j in cand])
                keep = mac(shapes[:, idx], g_ref[None, :]) >= mac_min
                cand, shapes = cand[keep], shapes[keep]
            if np.unique(poles.order[cand]).size < min_poles:
                continue
            j = int(np.argsort(poles.frequency_hz[cand])[cand.size // 2])
            est = res.estimate
            est.modes.append(Mode(float(poles.frequency_hz[cand[j]]), float(poles.damping_ratio[cand[j]]),
                                  shapes[j], n_poles=int(cand.size)))
            est.modes.sort(key=lambda m: m.frequency_hz)
            added += 1
    return added
