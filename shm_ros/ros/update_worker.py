"""The update node's sampling process (no ROS here: it is imported by a spawned interpreter).

Sampling is Python-bound (it holds the GIL most of the time) and may run for minutes; in a process of
its own it neither slows down the node's executor nor keeps the node from stopping: the node
terminates it. The structure is loaded and the model built once per process, by :func:`init`.
"""

from __future__ import annotations

import signal
from typing import Any

from shm_ros.core.bayes.update import Posterior, UpdateConfig

_state: dict[str, Any] = {}


def init(structure: str) -> None:
    """Pool initializer: load the structure and build its model."""
    from shm_ros.core.models import build_model
    from shm_ros.io.structure import load_structure

    # Ctrl-C in a terminal reaches the whole process group: the node decides when this process
    # ends (it terminates it on shutdown), so a run is not torn down half-way by the signal.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    spec = load_structure(structure)
    _state.update(spec=spec, model=build_model(spec))
    _warm_up()


def _warm_up() -> None:
    """Pay the chain diagnostics' one-off start (its imports, about 1 s)
    now, while the graph starts, rather than after the window that triggers the first run."""
    import numpy as np

    from shm_ros.core.bayes.diagnostics import chain_diagnostics

    chain_diagnostics(np.random.default_rng(0).standard_normal((4, 20, 1)))


def ready() -> bool:
    """A no-op task: submitted at start so that the process is up before the first run."""
    return "model" in _state


def run(windows: list, kind: str, config: UpdateConfig, warm_start: Posterior | None) -> Posterior:
    """Update (warm-started) from the windows received: ``kind`` "tracked" - tracked rows, one
    column per tracked mode, paired with the model's modes once inside the updating; "estimates" -
    modal estimates, every window's modes paired with the model's (prior mean, the updating's gate)."""
    from shm_ros.core.bayes.update import update

    spec, model = _state["spec"], _state["model"]
    sensors = model.observed_sensors(spec.sensor_ids)
    if kind == "tracked":
        from shm_ros.core.bayes.tracked import observations_from_rows

        obs = observations_from_rows(windows, sensors)
    else:
        from shm_ros.core.bayes.pairing import observations_for_model
        from shm_ros.core.bayes.update import pairing_reference

        theta, gate = pairing_reference(model, config, spec.parameters)
        obs = observations_for_model(model, windows, sensors, theta=theta, gate=gate)
    return update(model, obs, config, spec.parameters, warm_start=warm_start)


def run_events(paths: list[str], modal: dict[str, dict[str, Any]], config: Any) -> Posterior:
    """The time-domain posterior of the event window files ``paths``, the modal posterior's
    parameter summaries ``modal`` as the prior (:mod:`shm_ros.core.predict.event_calibration`;
    ``config`` an :class:`~shm_ros.core.predict.event_calibration.EventCalibrationConfig`)."""
    from shm_ros.core.predict.event_calibration import calibrate_on_events
    from shm_ros.io.window_files import load_window

    windows = [load_window(p) for p in paths]
    return calibrate_on_events(_state["model"], _state["spec"], windows, modal, config)
