"""Setups merged offline from arrays (recordings without tf): one call, either merge.

Each setup's channels are pre-processed (:func:`shm_ros.core.preprocess.preprocess`, e.g. decimated
to a common rate) and the setups merged after (``post``) or before (``pre``) identification. The
channels of all setups must measure one quantity (accelerations): a velocity leads an acceleration
by 90 degrees, so mixed channels give shapes whose parts are imaginary against each other.

After the post merge each mode's roving components come from the references' transmissibility in
every setup (:func:`~shm_ros.core.roving.transmissibility.apply_transmissibility`, the step the tf
pipeline uses), with its standard error as ``shape_std``; ``transmissibility=False`` keeps the
setups' rescaled identified components. Each setup's channels are put references first for it.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from shm_ros.core.identify import IdentifyConfig, identify_array
from shm_ros.core.preprocess import PreprocessConfig, preprocess
from shm_ros.core.roving.merge_post import GlobalMode, merge_post
from shm_ros.core.roving.merge_pre import merge_pre
from shm_ros.core.roving.transmissibility import apply_transmissibility
from shm_ros.errors import InputError

__all__ = ["MergeMethod", "merge_arrays"]


class MergeMethod(enum.StrEnum):
    POST = "post"  # each setup identified, modes rescaled through the references
    PRE = "pre"  # one subspace model over all setups


def merge_arrays(datasets: Sequence[np.ndarray], channels: Sequence[Sequence[str]], references: Sequence[str],
                 sample_rate_hz: float, config: IdentifyConfig, method: MergeMethod | str = MergeMethod.POST,
                 preprocess_config: PreprocessConfig | None = None, transmissibility: bool = True
                 ) -> tuple[list[GlobalMode], list[str]]:
    """Global modes of setups given as arrays (n_j, c_j) with their channel names (see module doc).
    ``config`` is used as given (block rows, orders, picking); its reference channels are set to
    ``references``. Returns the modes and notes."""
    method = MergeMethod(method)
    ordered = [_references_first(y, list(n), references, k) for k, (y, n) in enumerate(zip(datasets, channels,
                                                                                             strict=True))]
    preps = [preprocess(y, sample_rate_hz, n, preprocess_config) for y, n in ordered]
    rates = {p.sample_rate_hz for p in preps}
    if len(rates) != 1:
        raise InputError(f"setups at different rates after pre-processing: {sorted(rates)}")
    cfg = replace(config, reference_channels=list(references))
    notes = [f"{len(preps)} setups at {preps[0].sample_rate_hz:g} Hz, merged {method.value}-identification"]
    if method == MergeMethod.POST:
        estimates = [identify_array(p, cfg).estimate for p in preps]
        modes = merge_post(estimates, references)
        if transmissibility:
            apply_transmissibility(modes, [p.data for p in preps], [p.sample_rate_hz for p in preps], estimates,
                                   list(references))
            notes.append("roving components from the references' transmissibility on the merged reference shapes")
        return modes, notes
    modes, more = merge_pre([p.data for p in preps], [p.channel_names for p in preps], references,
                            preps[0].sample_rate_hz, cfg)
    return modes, notes + more


def _references_first(y: np.ndarray, names: list[str], references: Sequence[str], k: int
                      ) -> tuple[np.ndarray, list[str]]:
    """Setup ``k``'s channels (and names) reordered so that the references come first."""
    missing = [r for r in references if r not in names]
    if missing:
        raise InputError(f"setup {k + 1}: reference channel(s) {missing} not among its channels {names}")
    if y.ndim != 2 or y.shape[1] != len(names):
        raise InputError(f"setup {k + 1}: {len(names)} channel names for data of shape {y.shape}")
    order = [names.index(r) for r in references] + [i for i, n in enumerate(names) if n not in references]
    return np.asarray(y)[:, order], [names[i] for i in order]
