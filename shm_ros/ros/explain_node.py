"""explain: tracked modes in, verdicts on missing physics out (docs/explain.md, docs/interfaces.md §5).

Accumulates the track node's ``shm/tracked_modes`` (one row per window; a row sent again counts
once). Once ``min_windows`` rows have arrived, and again each time the count reaches the next step
of ``min_new_windows`` after them (:mod:`shm_ros.ros.run_schedule`: a restarted node that takes up
the rows in one burst runs at the same counts) or when a replay ends (``shm/replay/done``), it
explains all rows so far in a worker process (:mod:`shm_ros.ros.explain_worker`, the executor
never waits) and publishes a ``Verdict`` on ``shm/verdict`` (latched) when it is the first or when
the set of accepted physics or whether the model fits changed, i.e. when the support for a missing
effect crossed its threshold. ``output_dir`` gets verdict.json, the figures' numbers and report.html after every run.

**Event series** (docs/explain.md, Time domain): with a structure that declares a measured input, the
node also keeps the event windows of ``shm/windows`` (those ingest flags as events, docs/interfaces.md
§1, the newest ``max_events``) and, once ``min_events`` have arrived and again after every new one,
explains them in the time domain (amplitude-dependent stiffness and damping,
:func:`shm_ros.core.explain.timedomain.explain_events`, options ``time_domain.*``) in the same worker;
its verdicts go out on ``shm/verdict`` too (``kind`` "events", NRMS fields set) when their accepted
physics changed, and into ``output_dir/events``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rclpy.publisher import Publisher

from shm_ros.core.config import option
from shm_ros.core.explain.config import ExplainConfig
from shm_ros.core.explain.timedomain import TimeDomainConfig
from shm_ros.io.faults import fault_point
from shm_ros.ros import explain_worker, topics
from shm_ros.ros.convert import tracked_row_from_msg, window_from_msg
from shm_ros.ros.managed import ManagedNode
from shm_ros.ros.node_main import delivered, spin
from shm_ros.ros.params import ParameterError, load_config
from shm_ros.ros.qos import latched_qos, stream_qos
from shm_ros.ros.run_schedule import run_due
from shm_ros.ros.timers import steady_timer
from shm_ros.ros.worker_pool import WorkerPool


@dataclass
class ExplainNodeConfig:
    structure: str | None = option(None, "structure file (YAML, docs/interfaces.md §2); required")
    min_windows: int = option(24, "tracked windows received before the first run")
    min_new_windows: int = option(144, "tracked windows between runs: the next run comes when the count "
                                  "reaches min_windows + k x this (144: a day of 10-minute windows)")
    output_dir: str | None = option(None, "directory of verdict.json and report.html, rewritten after "
                                    "every run (unset: not written); the event series' in its 'events' folder")
    events: str = option("auto", "explain the event windows in the time domain: auto (when the structure "
                         "declares a measured input), on, off", choices=("auto", "on", "off"))
    min_events: int = option(3, "event windows received before the first time-domain run (then after every "
                             "new one)")
    max_events: int = option(24, "event windows kept for the time-domain runs, the newest (each run fits them "
                             "all: cost grows with their number)")
    time_domain: TimeDomainConfig = field(default_factory=TimeDomainConfig)


def explains_events(mode: str, has_input: bool) -> bool:
    """Whether the node explains event windows: its ``events`` parameter and the structure's input."""
    return mode == "on" or (mode == "auto" and has_input)


def verdict_to_msg(v: dict[str, Any]) -> Any:
    """verdict.json's content -> ``shm_interfaces/msg/Verdict``."""
    from shm_interfaces.msg import MissingPhysics, Verdict

    msg = Verdict()
    m = v["mismatch"]
    msg.mismatch_modes = [int(k) for k in m["modes"]]
    msg.mismatch_sensors = [str(s) for s in m["sensors"]]
    msg.covariate_names = list(m["covariates"])
    msg.covariate_correlations = [float(x) for x in m["covariates"].values()]
    msg.summary = str(m["summary"])
    for e in v["missing_physics"]:
        params = {k: float(x) for k, x in e.get("parameters", {}).items()}
        msg.missing_physics.append(MissingPhysics(
            name=e["name"], form=str(e.get("form", "")), where=str(e.get("where", "")),
            parameter_names=list(params), parameter_values=list(params.values()),
            log_evidence_gain=float(e["log_evidence_gain"]), form_fits=e.get("form_fits") is not False,
            form_fits_known=e.get("form_fits") is not None, downgraded_by=str(e.get("downgraded_by") or "")))
    f, nan = v["fit"], float("nan")
    msg.before_frequency_rmse_pct = float(f["before"].get("frequency_rmse_pct", nan))
    msg.before_mac_mean = float(f["before"].get("mac_mean", nan))
    msg.after_frequency_rmse_pct = float(f["after"].get("frequency_rmse_pct", nan))
    msg.after_mac_mean = float(f["after"].get("mac_mean", nan))
    msg.held_out_before_frequency_rmse_pct = float(f["held_out"]["before"].get("frequency_rmse_pct", nan))
    msg.held_out_after_frequency_rmse_pct = float(f["held_out"]["after"].get("frequency_rmse_pct", nan))
    msg.before_nrms_pct = float(f["before"].get("nrms_pct", nan))
    msg.after_nrms_pct = float(f["after"].get("nrms_pct", nan))
    msg.held_out_before_nrms_pct = float(f["held_out"]["before"].get("nrms_pct", nan))
    msg.held_out_after_nrms_pct = float(f["held_out"]["after"].get("nrms_pct", nan))
    msg.kind = "events" if "nrms_pct" in f["before"] else "modes"
    w = f.get("residual_whiteness") or {}
    msg.whiteness_modes = [int(k) for k in w.get("mode_numbers", [])]
    msg.lag1_before = [float(x) for x in w.get("lag1_before", [])]
    msg.lag1_after = [float(x) for x in w.get("lag1_after", [])]
    msg.still_structured_modes = [int(k) for k in w.get("still_structured", [])]
    msg.status = str(v.get("status", "ok"))
    ratio = v.get("fit_ratio")
    msg.fit_ratio = nan if ratio is None else float(ratio)
    msg.model_fits = bool(v.get("model_fits"))
    msg.model_fits_known = v.get("model_fits") is not None
    return msg


class ExplainNode(ManagedNode):
    """Parameters: every option of :class:`ExplainConfig` and of :class:`ExplainNodeConfig`."""

    kind = "explain"

    def setup(self) -> None:
        self.config = load_config(self, ExplainConfig)
        self.settings = load_config(self, ExplainNodeConfig)
        if not self.settings.structure:
            raise ParameterError(f"{self.get_name()}: parameter 'structure' (path of the structure YAML) is required")
        from shm_ros.core.models import build_model
        from shm_ros.io.structure import load_structure

        model = build_model(load_structure(self.settings.structure))  # a bad file stops the node at once
        mode = self.settings.events
        self.with_events = explains_events(mode, bool(model.inputs))
        if mode == "on" and not model.inputs:
            raise ParameterError(f"{self.get_name()}: events:=on needs a measured input in {self.settings.structure} "
                             "('input'/'inputs')")
        self.events: dict[str, Any] = {}
        self.events_seen: set[str] = set()  # every event window id received (runs go on after the cap)
        self.events_used = 0
        self.event_future: Any = None
        self.event_started = 0.0
        self.rows: dict[str, Any] = {}
        self.used = 0
        self.flush = False  # a replay ended: from now on, run on whatever new rows have arrived
        self.future: Any = None
        self.started = 0.0
        # the accepted physics (and whether the model fits) of the last verdict of each kind
        self.last: dict[str, tuple[str, ...]] = {}
        self.runs = 0
        self.diag.summarize(lambda: (
            "ok", f"{len(self.rows)} windows received, {self.runs} runs"
            + (", explaining" if self.future is not None or self.event_future is not None else ", idle")
            + (f"; {len(self.events_seen)} event windows" if self.with_events else ""),
            {"received": len(self.rows), "events": len(self.events_seen)}))
        self.pub: Publisher[Any] = self.create_publisher(
            topics.message_class(topics.TYPES[topics.VERDICT]), topics.VERDICT, latched_qos())
        self.create_subscription(topics.message_class(topics.TYPES[topics.TRACKED_MODES]), topics.TRACKED_MODES,
                                 self._on_row, stream_qos())
        self.create_subscription(topics.message_class(topics.TYPES[topics.REPLAY_DONE]), topics.REPLAY_DONE,
                                 self._on_replay_done, latched_qos())
        if self.with_events:
            self.create_subscription(topics.message_class(topics.TYPES[topics.WINDOWS]), topics.WINDOWS,
                                     self._on_window, stream_qos())
        self.workers = WorkerPool(explain_worker.init, (self.settings.structure,), explain_worker.ready)
        steady_timer(self, 0.25, self._poll)

    def teardown(self) -> None:
        self.workers.shutdown()

    def _on_row(self, msg: Any) -> None:
        try:
            self.rows[msg.window_id] = tracked_row_from_msg(msg)
        except (ValueError, TypeError) as exc:  # one bad message must not take the node down
            self.diag.report("warn", f"tracked row {msg.window_id!r} skipped: {exc}", "input")

    def _on_window(self, msg: Any) -> None:
        if not msg.is_event:  # only event windows are kept (a long campaign's windows are not)
            return
        try:
            w = window_from_msg(msg)
        except (ValueError, TypeError) as exc:  # one bad message must not take the node down
            self.diag.report("warn", f"window {msg.window_id!r} skipped: {exc}", "input")
            return
        self.events[w.window_id] = w
        self.events_seen.add(w.window_id)
        while len(self.events) > max(self.settings.max_events, 1):
            del self.events[min(self.events, key=lambda k: self.events[k].start_ns)]

    def _on_replay_done(self, _msg: Any) -> None:
        self.flush = True

    def _due(self) -> bool:
        n = len(self.rows)
        if n < self.settings.min_windows or n == self.used:
            return False
        return self.flush or run_due(n, self.used, self.settings.min_windows, self.settings.min_new_windows)

    def _poll(self) -> None:
        if self.future is not None and self.future.done():
            self._collect()
        if self.future is None and self._due():
            self.used, self.started = len(self.rows), time.time()
            self.future = self.workers.submit(explain_worker.run, list(self.rows.values()), self.config,
                                              self.settings.output_dir)
            self.diag.report("ok", f"explaining {self.used} windows", "progress")
        if self.event_future is not None and self.event_future.done():
            self._collect_events()
        n = len(self.events_seen)
        if self.event_future is None and n >= max(self.settings.min_events, 1) and n != self.events_used:
            self.events_used, self.event_started = n, time.time()
            out = str(Path(self.settings.output_dir) / "events") if self.settings.output_dir else None
            self.event_future = self.workers.submit(explain_worker.run_events, list(self.events.values()),
                                                    self.settings.time_domain, out)
            self.diag.report("ok", f"explaining {n} event windows in the time domain", "progress")
        self.diag.publish()

    def _collect_events(self) -> None:
        future, self.event_future = self.event_future, None
        self._finish(future, self.event_started, "events verdict", "event windows", self.events_used, "events")

    def _collect(self) -> None:
        future, self.future = self.future, None
        if self._finish(future, self.started, "verdict", "windows", self.used, "windows") is not None:
            self.runs += 1

    def _finish(self, future: Any, started: float, name: str, unit: str, count: int, key: str) -> tuple | None:
        """A run's end: its diagnostics (status ``name``, value ``key`` = ``count`` of ``unit`` explained),
        and its Verdict published when the accepted physics changed from the last of its kind, i.e. when
        the support for an effect crossed its threshold. None when the run failed."""
        took = time.time() - started
        try:
            verdict, _ = future.result()
        except Exception as exc:  # a failed run (or a lost worker) must not take the node down
            self.diag.report("error", f"explain with {count} {unit} failed: {exc}", name, **{key: count})
            if "BrokenProcessPool" in type(exc).__name__:
                self.workers.restart()
            return None
        accepted = tuple(e["name"] for e in verdict["missing_physics"])
        fits = {True: "model fits", False: f"model does NOT fit (fit ratio {verdict.get('fit_ratio')})",
                None: "fit ratio unknown"}[verdict.get("model_fits")]
        text = f"{', '.join(accepted) or 'nothing named'}; {fits}"
        level = "warn" if verdict.get("model_fits") is False else "ok"
        self.diag.report(level, f"{count} {unit} in {took:.1f} s: {text}", name, **{key: count})
        state = (*accepted, f"model_fits={verdict.get('model_fits')}")
        if state != self.last.get(name):
            self.last[name] = state
            self.pub.publish(verdict_to_msg(verdict))
            fault_point(self.get_name(), "published", delivered(self.pub))  # a test hook: killed after a verdict
            self.get_logger().info(f"verdict from {count} {unit}: {text}")
        return accepted

def make_node(name: str, parameters: dict[str, Any], namespace: str = "") -> ExplainNode:
    return ExplainNode(name, parameters, namespace)


def main(args: list[str] | None = None) -> int:
    return spin(lambda: ExplainNode(), args)


if __name__ == "__main__":
    raise SystemExit(main())
