"""update: tracked modes in, posterior summary out (re-run as new windows arrive).

Accumulates the track node's ``shm/tracked_modes`` (one row per window, mode identities kept
across windows); on the first ``min_windows`` windows, and then whenever the count reaches the
next step of ``min_new_windows`` after them (:mod:`shm_ros.ros.run_schedule`), it builds one column
per tracked mode and calls :func:`shm_ros.core.bayes.update.update` (which pairs the tracked
modes with the model's modes once, behind the gate), warm-started from the last posterior; publishes ``shm/posterior``
(latched) and writes ``posterior.json`` to ``output_dir`` when set. With ``input: estimates`` it
runs without a track node: it takes ``shm/modal_estimates`` and pairs every window's modes with
the prior-mean model instead (a spurious mode near a model frequency can then pass for a mode
the window missed).

With ``calibration_windows`` (window files of recorded events, e.g. earthquakes with a measured
input) the node, after each modal posterior, calibrates on those events in the time domain with the
modal posterior as the prior (:mod:`shm_ros.core.predict.event_calibration`; sampler: the
``calibration.*`` parameters) and writes that posterior to ``<output_dir>/time`` (its
``diagnostics.likelihood`` is ``time``): the one a predict node given the same events predicts with.
It is not published on ``shm/posterior``, which stays the modal one; the ``posterior_time``
diagnostic reports it.

A run (seconds to minutes) goes to a worker process (:mod:`shm_ros.ros.update_worker`): the node
keeps receiving meanwhile. Windows that arrive during a run are kept; when it is done, the next
run starts at once if enough new windows came, with every window received by then (so at most one
run is ever waiting). A timer in the executor thread collects the finished run and publishes. The
``progress`` diagnostic says what the node is doing ("sampling, 30 windows, started at ...") with
the values ``received`` (windows so far), ``sampling`` and ``run_windows``; it is published on
every window received, at the start and end of a run and every 30 s during one.
"""

from __future__ import annotations

import enum
import time
from concurrent.futures import Future
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from rclpy.publisher import Publisher

from shm_ros.core.bayes.update import Posterior, UpdateConfig
from shm_ros.core.config import option
from shm_ros.core.predict.event_calibration import EventCalibrationConfig
from shm_ros.io.faults import fault_point
from shm_ros.ros import topics, update_worker
from shm_ros.ros.convert import estimate_from_msg, posterior_to_msg, tracked_row_from_msg
from shm_ros.ros.managed import ManagedNode
from shm_ros.ros.node_main import delivered, spin
from shm_ros.ros.params import ParameterError, check_window_files, load_config
from shm_ros.ros.qos import latched_qos, stream_qos
from shm_ros.ros.run_schedule import next_run_at, run_due
from shm_ros.ros.timers import steady_timer
from shm_ros.ros.worker_pool import WorkerPool

PROGRESS_EVERY_S = 30.0


class UpdateInput(enum.StrEnum):
    TRACKED = "tracked"  # the track node's rows: identities across windows, paired with the model once
    ESTIMATES = "estimates"  # raw modal estimates, each window paired with the prior-mean model


@dataclass
class UpdateNodeConfig:
    """Settings of the node itself (the updating's are :class:`UpdateConfig`)."""

    structure: str | None = option(None, "structure file (YAML, docs/interfaces.md §2); required")
    input: str = option("tracked", "what the node updates from: tracked (the track node's "
                        "shm/tracked_modes) or estimates (shm/modal_estimates, without a track node)",
                        choices=UpdateInput)
    min_windows: int = option(10, "windows received before the first run")
    min_new_windows: int = option(10, "windows between runs: the next run comes when the count of "
                                  "windows received reaches min_windows + k x this, on every window by then")
    output_dir: str | None = option(None, "directory of posterior.json, rewritten after every run "
                                    "(unset: not written)")
    calibration_windows: list[str] | None = option(
        None, "window files (.npz, as `shm-ros ingest --windows` writes) of recorded events: after each modal "
        "posterior they calibrate in the time domain, the modal posterior as the prior, written to "
        "<output_dir>/time (needs output_dir; unset: no time-domain step)")
    calibration: EventCalibrationConfig = field(default_factory=EventCalibrationConfig)  # calibration.* parameters


class UpdateNode(ManagedNode):
    """Parameters: every option of :class:`UpdateConfig` and of :class:`UpdateNodeConfig`."""

    kind = "update"

    def setup(self) -> None:
        self.config = load_config(self, UpdateConfig)
        self.settings = load_config(self, UpdateNodeConfig)
        if not self.settings.structure:
            raise ParameterError(f"{self.get_name()}: parameter 'structure' (path of the structure YAML) "
                             "is required")
        self.structure: str = self.settings.structure
        from shm_ros.core.models import build_model
        from shm_ros.io.structure import load_structure

        # load here too: a bad structure file stops the node at once, not at its first run
        self.spec = load_structure(self.structure)
        build_model(self.spec)
        self.output_dir = Path(self.settings.output_dir) if self.settings.output_dir else None
        self.events = list(self.settings.calibration_windows or [])
        self.events_config = self.settings.calibration
        if self.events:
            _check_events(self.get_name(), self.events, self.output_dir)
        self.events_future: Future | None = None  # the time-domain step of the last modal posterior
        self.events_started = 0.0
        self.events_prior: Posterior | None = None  # the modal posterior of the last time-domain step
        try:
            self.input = UpdateInput(self.settings.input)
        except ValueError:
            raise ParameterError(f"{self.get_name()}: parameter 'input' must be one of "
                             f"{[i.value for i in UpdateInput]}, got {self.settings.input!r}") from None
        # window id -> tracked row or estimate: a row sent again (a restarted track node) counts once
        self.windows: dict[str, Any] = {}
        self.posterior: Posterior | None = None  # the last one: warm start of the next run
        self.used = 0  # windows of the latest run
        self.future: Future | None = None
        self.run_windows = 0
        self.run_started = 0.0  # time.time() of the start of the current run
        self._progress_at = 0.0
        self.diag.summarize(lambda: (
            "ok", f"{len(self.windows)} windows received"
            + (f", sampling {self.run_windows} of them" if self.future is not None else ", idle"),
            {"received": len(self.windows), "sampling": self.future is not None}))
        self.pub: Publisher[Any] = self.create_publisher(
            topics.message_class(topics.TYPES[topics.POSTERIOR]), topics.POSTERIOR, latched_qos())
        topic = topics.TRACKED_MODES if self.input is UpdateInput.TRACKED else topics.MODAL_ESTIMATES
        self.create_subscription(topics.message_class(topics.TYPES[topic]), topic, self._on_window,
                                 stream_qos())
        self.workers = WorkerPool(update_worker.init, (self.structure,), update_worker.ready)
        steady_timer(self, 0.25, self._poll)

    def teardown(self) -> None:
        """Stop a run in progress: the worker process is terminated, not waited for."""
        self.workers.shutdown()

    # runs -------------------------------------------------------------------------------------

    def _on_window(self, msg) -> None:
        convert = tracked_row_from_msg if self.input is UpdateInput.TRACKED else estimate_from_msg
        self.windows[msg.window_id] = convert(msg)
        if self.future is None:
            self._maybe_start()
        self._progress()

    def _maybe_start(self) -> None:
        n = len(self.windows)
        if run_due(n, self.used, self.settings.min_windows, self.settings.min_new_windows):
            self.used = self.run_windows = n
            self.run_started = time.time()
            args = (list(self.windows.values()), self.input.value, self.config, self.posterior)
            self.future = self.workers.submit(update_worker.run, *args)

    def _poll(self) -> None:
        """Timer (executor thread): collect a finished run, publish it, start the next one."""
        if self.events_future is not None and self.events_future.done():
            self._collect_events()
        if self.future is None:
            return
        if not self.future.done():
            if time.time() - self._progress_at >= PROGRESS_EVERY_S:
                self._progress()
            return
        future, self.future = self.future, None
        n, took = self.run_windows, time.time() - self.run_started
        try:
            posterior = future.result()
        except BrokenProcessPool as exc:  # the worker died (e.g. out of memory): start another
            self.diag.report("error", f"update with {n} windows failed: worker process lost ({exc})",
                             "posterior")
            self.workers.restart()
        except Exception as exc:  # a failed update must not take the node down
            self.diag.report("error", f"update with {n} windows failed: {exc}", "posterior")
        else:
            self._publish(posterior, n, took)
        self._maybe_start()
        self._progress()

    def _publish(self, posterior: Posterior, n: int, took: float) -> None:
        self.posterior = posterior
        self.pub.publish(posterior_to_msg(posterior.summary_record(self.spec.name)))
        # a test hook: killed after publishing a posterior (delivered)
        fault_point(self.get_name(), "published", delivered(self.pub))
        if self.output_dir is not None:
            from shm_ros.io.posterior_files import write_posterior

            write_posterior(self.output_dir, posterior, asdict(self.config) | {"n_windows": n}, self.config.seed)
        summary = ", ".join(f"{k} {v.mean:.4f}±{v.std:.4f}" for k, v in posterior.parameters.items())
        level = "ok" if posterior.diagnostics.get("converged", False) else "warn"
        self.diag.report(level, f"{n} windows in {took:.1f} s: {summary}", "posterior")
        self.get_logger().info(f"posterior from {n} windows: {summary}")
        self._start_events()

    def _start_events(self) -> None:
        """The time-domain step on the events, the latest modal posterior as the prior (one at a time:
        a modal posterior that arrives during a step starts the next one when it is done)."""
        if not self.events or self.posterior is None or self.events_future is not None:
            return
        modal = {k: v.to_dict() for k, v in self.posterior.parameters.items()}
        self.events_prior, self.events_started = self.posterior, time.time()
        self.events_future = self.workers.submit(update_worker.run_events, self.events, modal, self.events_config)
        self.diag.report("ok", f"time-domain step on {len(self.events)} events started", "posterior_time")

    def _collect_events(self) -> None:
        """Write the finished time-domain posterior (``<output_dir>/time``)."""
        future, self.events_future = self.events_future, None
        if future is None or self.output_dir is None:  # setup refuses events without output_dir
            return
        took = time.time() - self.events_started
        try:
            posterior = future.result()
        except BrokenProcessPool as exc:
            self.diag.report("error", f"time-domain step failed: worker process lost ({exc})", "posterior_time")
            self.workers.restart()
            return
        except Exception as exc:  # a failed step must not take the node down
            self.diag.report("error", f"time-domain step failed: {exc}", "posterior_time")
            return
        from shm_ros.io.posterior_files import write_posterior

        config = asdict(self.events_config) | {"likelihood": "time", "calibration_windows": self.events,
                                                "prior": str(self.output_dir / "posterior.json")}
        write_posterior(self.output_dir / "time", posterior, config, self.events_config.seed)
        summary = ", ".join(f"{k} {v.mean:.4f}±{v.std:.4f}" for k, v in posterior.parameters.items())
        level = "ok" if posterior.diagnostics.get("converged", False) else "warn"
        self.diag.report(level, f"{len(self.events)} events in {took:.1f} s: {summary}", "posterior_time")
        self.get_logger().info(f"time-domain posterior from {len(self.events)} events: {summary}")
        if self.posterior is not self.events_prior:  # a newer modal posterior came meanwhile
            self._start_events()

    def _progress(self) -> None:
        received = len(self.windows)
        if self.future is not None:
            started = datetime.fromtimestamp(self.run_started, UTC).isoformat(timespec="seconds")
            waiting = received - self.run_windows
            text = f"sampling, {self.run_windows} windows, started at {started}" + (
                f"; {waiting} new windows since" if waiting else "")
            self.diag.report("ok", text, "progress", received=received, sampling="true",
                             run_windows=self.run_windows, started_at=started)
        else:
            need = next_run_at(self.used, self.settings.min_windows, self.settings.min_new_windows)
            text = f"waiting: {received} of {need} windows for the next run"
            self.diag.report("ok", text, "progress", received=received, sampling="false",
                             run_windows=self.used)
        self.diag.publish()
        self._progress_at = time.time()


def _check_events(name: str, paths: list[str], output_dir: Path | None) -> None:
    """Calibration windows: readable window files, and a folder to write the posterior to."""
    if output_dir is None:
        raise ParameterError(f"{name}: parameter 'calibration_windows' needs 'output_dir' (the time-domain "
                             "posterior is written to <output_dir>/time)")
    check_window_files(name, "calibration_windows", paths)


def make_node(name: str, parameters: dict[str, Any], namespace: str = "") -> UpdateNode:
    return UpdateNode(name, parameters, namespace)


def main(args: list[str] | None = None) -> int:
    return spin(lambda: UpdateNode(), args)


if __name__ == "__main__":
    raise SystemExit(main())
