"""A recording -> its tracked modal data: windows (ingest) -> modes per window (identify) -> mode
identities across windows (the tracker of ``shm-ros track``) -> one column per tracked mode.

Shared by the commands that accept ``--bag`` where they work on modal data (``update``, ``explain``).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

import numpy as np


def _stderr(prog: str) -> Callable[[str], None]:
    return lambda text: print(f"{prog}: note: {text}", file=sys.stderr)


def tracked_observations_from_bag(bag: str, spec: Any, observed: list[str], window_s: float | None = None,
                                  note: Callable[[str], None] | None = None) -> Any:
    """:class:`~shm_ros.core.observations.ModalObservations` of ``bag`` with shapes at
    ``observed`` (the model's sensors). Windows that cannot be identified are noted and skipped."""
    from threadpoolctl import threadpool_limits

    from shm_ros.core.bayes.tracked import observations_from_tracking
    from shm_ros.core.identify import identify_window
    from shm_ros.io.recording import windows_from_bag

    note = note or _stderr("shm-ros")
    windows, _ = windows_from_bag(bag, spec, window_s or 600.0)
    if not windows:
        raise ValueError(f"{bag}: no usable window in the recording")
    estimates = []
    with threadpool_limits(1, "blas"):  # same result whatever the machine's thread count
        for w in windows:
            try:
                estimates.append(identify_window(w))
            except (ValueError, np.linalg.LinAlgError) as exc:
                note(f"window {w.window_id}: not identified ({exc})")
    if estimates:  # auto: input-output SSI when the structure's input sensor is recorded
        note(f"windows identified with {', '.join(sorted({e.method for e in estimates}))}")
    try:  # the tracker's defaults, as `shm-ros track`
        return observations_from_tracking(estimates, observed)
    except ValueError as exc:
        raise ValueError(f"{bag}: {exc}") from None
