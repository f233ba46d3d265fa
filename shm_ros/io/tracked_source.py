"""A recording -> its tracked modal data: windows (ingest) -> modes per window (identify) -> mode
identities across windows (the tracker of ``shm-ros track``) -> one column per tracked mode.

Shared by the commands that accept ``--bag`` where they work on modal data (``update``, ``explain``).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

import numpy as np

from shm_ros.errors import InputError, NoWindowsError


def event_ingest(spec: Any) -> Any:
    """The ingest settings of a recording of a structure with a measured input: a window is an event
    when STA/LTA triggers or its peak reaches the strong-motion trigger (a 20 s record that starts a
    few seconds before its onset leaves the long-term average too little quiet to trigger). None (the
    ingest defaults) without an input."""
    from shm_ros.core.ingest.config import EventDetector, IngestConfig

    return IngestConfig(event_detector=EventDetector.EITHER) if spec.input_sensor_ids() else None


def _stderr(prog: str) -> Callable[[str], None]:
    return lambda text: print(f"{prog}: note: {text}", file=sys.stderr)


def tracked_observations_from_bag(bag: str, spec: Any, observed: list[str], window_s: float | None = None,
                                  note: Callable[[str], None] | None = None) -> Any:
    """:class:`~shm_ros.core.observations.ModalObservations` of ``bag`` with shapes at
    ``observed`` (the model's sensors). Windows that cannot be identified are noted and skipped.

    With a measured input in the structure, a window with a strong-motion peak counts as an event
    even where STA/LTA cannot trigger (a short earthquake record), so that its amplitude covariates
    (``pga_m_s2``) are those of an event; the event windows found are noted."""
    from threadpoolctl import threadpool_limits

    from shm_ros.core.bayes.tracked import observations_from_tracking
    from shm_ros.core.identify import identify_window
    from shm_ros.core.input_driven import input_driven_modes
    from shm_ros.core.tracking import TrackingConfig
    from shm_ros.core.tracking.batch import NoTrackedModes
    from shm_ros.io.recording import windows_from_bag

    note = note or _stderr("shm-ros")
    windows, _ = windows_from_bag(bag, spec, window_s, config=event_ingest(spec))
    events = sum(w.is_event for w in windows)
    if events and spec.input_sensor_ids():
        note(f"{events} of {len(windows)} window(s) are events with the measured input "
             f"{', '.join(spec.input_sensor_ids())}: explained per event (modal estimates with their amplitude "
             "covariates); --events explains them in the time domain")
    if not windows:
        raise NoWindowsError(f"{bag}: no usable window in the recording")
    estimates = []
    dropped = 0
    with threadpool_limits(1, "blas"):  # same result whatever the machine's thread count
        for w in windows:
            try:
                est = identify_window(w)
            except (ValueError, np.linalg.LinAlgError) as exc:
                note(f"window {w.window_id}: not identified ({exc})")
                continue
            est, left_out = input_driven_modes(w, est)
            dropped += left_out
            estimates.append(est)
    if not estimates:
        raise NoWindowsError(f"{bag}: none of its {len(windows)} window(s) could be identified")
    note(f"windows identified with {', '.join(sorted({e.method for e in estimates}))}")
    if dropped:
        from shm_ros.core.input_driven import MIN_SHARE

        note(f"{dropped} identified mode(s) left out: each carries less than {MIN_SHARE:.0%} of the "
             "recorded response from the measured input (noise or an unmeasured input)")
    try:  # the tracker's defaults, as `shm-ros track`
        return observations_from_tracking(estimates, observed)
    except NoTrackedModes as exc:  # few windows (a handful of events) never stop the analysis
        note(f"{exc}; the modes are matched to the structure's model instead (a mode found in two windows)")
    except ValueError as exc:
        raise InputError(f"{bag}: {exc}") from None
    few = TrackingConfig(reference_source="both", min_presence=min(0.5, 2.0 / len(estimates)))
    try:
        return observations_from_tracking(estimates, observed, few, structure=spec)
    except NoTrackedModes as exc:
        raise NoWindowsError(f"{bag}: no mode is found in two of its {len(estimates)} identified windows "
                             f"({exc})") from None
    except ValueError as exc:
        raise InputError(f"{bag}: {exc}") from None
