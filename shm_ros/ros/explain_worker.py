"""The explain node's worker process (no ROS here: it is imported by a spawned interpreter).

Explaining a campaign fits several candidate physics with their evidence: seconds to minutes of
Python-bound work, which runs here so that the node's executor keeps taking tracked rows.
"""

from __future__ import annotations

import signal
from typing import Any

_state: dict[str, Any] = {}


def init(structure: str) -> None:
    from shm_ros.core.models import build_model
    from shm_ros.io.structure import load_structure

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the node ends this process, not Ctrl-C
    spec = load_structure(structure)
    model = build_model(spec)
    _state.update(spec=spec, sensors=model.observed_sensors(spec.sensor_ids))


def ready() -> bool:
    return "spec" in _state


def run(rows: list, config: Any, output_dir: str | None) -> tuple[dict[str, Any], dict[str, Any]]:
    """Explain the tracked rows received so far (as ``shm-ros explain --modes`` on their table);
    writes verdict.json, its series and report.html into ``output_dir`` when given."""
    from shm_ros.core.bayes.tracked import observations_from_rows
    from shm_ros.core.explain.explain import explain

    obs = observations_from_rows(rows, _state["sensors"])
    verdict = explain(obs, _state["spec"], config)
    if output_dir:
        from dataclasses import asdict

        from shm_ros.io.verdict_files import write_verdict
        from shm_ros.report.build import build_report
        from shm_ros.report.inputs import ExplainInputs, ReportInputs

        write_verdict(output_dir, verdict, asdict(config) | {"n_windows": obs.n_windows})
        inputs = ReportInputs(title=f"shm_ros explain: {_state['spec'].name}")
        inputs.explain = ExplainInputs.from_files(output_dir)
        build_report(inputs, output_dir)
    return verdict.to_dict(), {"n_windows": obs.n_windows}


def run_events(windows: list, config: Any, output_dir: str | None) -> tuple[dict[str, Any], dict[str, Any]]:
    """Explain the event windows received so far in the time domain (as ``shm-ros explain --events``);
    writes verdict.json, its series and report.html into ``output_dir`` when given."""
    from shm_ros.core.explain.timedomain import explain_events
    from shm_ros.core.models import build_model
    from shm_ros.core.predict import event_from_window

    model = build_model(_state["spec"])
    windows = sorted(windows, key=lambda w: w.start_ns)  # in time order, as a recording gives them
    verdict = explain_events([event_from_window(w, model) for w in windows], _state["spec"], config)
    if output_dir:
        from dataclasses import asdict

        from shm_ros.io.verdict_files import write_verdict
        from shm_ros.report.build import build_report
        from shm_ros.report.inputs import ExplainInputs, ReportInputs

        write_verdict(output_dir, verdict, asdict(config) | {"n_events": len(windows)})
        inputs = ReportInputs(title=f"shm_ros explain (event series): {_state['spec'].name}")
        inputs.explain = ExplainInputs.from_files(output_dir)
        build_report(inputs, output_dir)
    return verdict.to_dict(), {"n_events": len(windows)}
