"""predict: windows in, response predictions out (docs/predict.md, docs/interfaces.md §7).

Subscribes to ``shm/windows`` and ``shm/posterior``. Every window that ingest flags as an event,
and any window named on ``shm/predict_request`` (std_msgs/String: a window id among the last
``keep_windows`` received; no service type is used because std_srvs is not a dependency), is
predicted with the posterior file ``posterior`` (re-read when it changes; a ``shm/posterior``
message marks that it did) or the nominal model without one, scored and published as
``ResponsePrediction`` on ``shm/prediction``. With ``wait_for_posterior_s`` > 0 the queued windows
wait until the update node has written the posterior (a graph that replays a recording delivers the
event windows long before the first posterior exists). With ``output_dir`` the node also writes
``prediction.json`` (Table 3 rows, scores, summary) and ``prediction_series.json`` after every
prediction, as ``shm-ros predict`` does. Predictions run one at a time in a worker process
(:mod:`shm_ros.ros.predict_worker`); a timer in the executor thread collects them.
"""

from __future__ import annotations

import time
from collections import OrderedDict, deque
from concurrent.futures import Future
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from rclpy.publisher import Publisher

from shm_ros.core.config import option
from shm_ros.core.predict import PredictConfig
from shm_ros.io.faults import fault_point
from shm_ros.ros import predict_worker, topics
from shm_ros.ros.convert import ns_to_time, window_from_msg
from shm_ros.ros.managed import ManagedNode
from shm_ros.ros.node_main import delivered, spin
from shm_ros.ros.params import ParameterError, check_window_files, load_config
from shm_ros.ros.qos import latched_qos, stream_qos
from shm_ros.ros.timers import steady_timer
from shm_ros.ros.worker_pool import WorkerPool

REQUEST = topics.PREDICT_REQUEST
MAX_FILED = 100  # predictions kept for output_dir's prediction.json (the newest)
MAX_SERIES = 20  # and for its prediction_series.json (the traces: tens of MB an event)


@dataclass
class PredictNodeConfig:
    structure: str | None = option(None, "structure file (YAML, docs/interfaces.md §2); required")
    posterior: str | None = option(None, "posterior.json or its folder (unset: the nominal model)")
    keep_windows: int = option(20, "windows kept for requests by id")
    wait_for_posterior_s: float = option(0.0, "windows to predict wait (queued, the executor runs on) until the "
                                         "posterior file and its samples exist, at most this long (wall clock, "
                                         "from the first queued window); then the nominal model is used "
                                         "(0: no wait)")
    calibration_windows: list[str] | None = option(None, "window files (.npz, as `shm-ros ingest --windows` writes) "
                                                   "of the events the posterior was calibrated on in the time "
                                                   "domain, two or more: the model error is learnt from them out "
                                                   "of sample (leave one event out); the posterior must then be "
                                                   "a time-domain one (diagnostics.likelihood 'time', e.g. the "
                                                   "update node's <output_dir>/time): a modal one is waited past "
                                                   "or, without a wait, not used; unset: the calibration's "
                                                   "in-sample error")
    output_dir: str | None = option(None, "directory of prediction.json and prediction_series.json (as `shm-ros "
                                    "predict` writes them; the series file with the newest 20 events' traces), "
                                    "rewritten after every prediction (unset: not written)")


def prediction_to_msg(pred: Any) -> Any:
    """``shm_interfaces/msg/ResponsePrediction`` of an ``EventPrediction``: every predicted location,
    row-major samples x channels."""
    msg = topics.message_class(topics.TYPES[topics.PREDICTION])()
    msg.header.stamp = ns_to_time(pred.start_ns)
    msg.window_id = pred.window_id
    msg.start = ns_to_time(pred.start_ns)
    msg.sample_rate_hz = float(pred.fs)
    msg.channel_names = [c.name for c in pred.channels]
    msg.measured = [bool(c.measured) for c in pred.channels]
    n = int(pred.channels[0].mean.size) if pred.channels else 0
    msg.n_samples = n
    nan = np.full(n, np.nan)
    msg.predicted_mean = np.column_stack([c.mean for c in pred.channels]).ravel().tolist()
    msg.predicted_std = np.column_stack([c.std for c in pred.channels]).ravel().tolist()
    msg.measured_values = np.column_stack([c.values if c.values is not None else nan
                                           for c in pred.channels]).ravel().tolist()
    msg.nrms_pct = [float(c.scores.get("nrms_pct", np.nan)) if c.measured else float("nan")
                    for c in pred.channels]
    return msg


class PredictNode(ManagedNode):
    """Parameters: every option of :class:`PredictConfig` and of :class:`PredictNodeConfig`."""

    kind = "predict"

    def setup(self) -> None:
        self.config = load_config(self, PredictConfig).validate()
        self.settings = load_config(self, PredictNodeConfig)
        if not self.settings.structure:
            raise ParameterError(f"{self.get_name()}: parameter 'structure' (path of the structure YAML) is required")
        from shm_ros.core.models import build_model
        from shm_ros.io.structure import load_structure

        self.structure: str = self.settings.structure
        model = build_model(load_structure(self.structure))  # a bad file stops the node at once
        calibration = tuple(self.settings.calibration_windows or ())
        _check_calibration(self.get_name(), calibration)
        # a structure without a measured input ('input'/'inputs') has nothing to drive a prediction
        # with: the node stays up (a graph may list it for every structure) and predicts nothing
        self.enabled = bool(model.inputs)
        if not self.enabled:
            self.get_logger().info(f"structure {self.structure} declares no measured input ('input'/'inputs'): "
                                   "predictions are off, windows are ignored")
        self.windows: OrderedDict[str, Any] = OrderedDict()
        self.queue: deque = deque()
        self.future: Future | None = None
        self.future_model = "nominal"
        self.done = 0
        self.diag.summarize(lambda: (
            "ok", f"{self.done} predictions, {len(self.queue)} waiting" if self.enabled
            else "off: the structure declares no measured input", {"predicted": self.done}))
        self.pub: Publisher[Any] = self.create_publisher(topics.message_class(topics.TYPES[topics.PREDICTION]),
                                         topics.PREDICTION, stream_qos())
        self.create_subscription(topics.message_class(topics.TYPES[topics.WINDOWS]), topics.WINDOWS,
                                 self._on_window, stream_qos())
        self.create_subscription(topics.message_class(topics.TYPES[topics.POSTERIOR]), topics.POSTERIOR,
                                 lambda _msg: None, latched_qos())  # the file is re-read when it changed
        self.create_subscription(topics.message_class("std_msgs/msg/String"), REQUEST, self._on_request,
                                 stream_qos())
        self.results: deque = deque(maxlen=MAX_FILED)  # (prediction, Table-3 row, model label) for output_dir
        self.waiting_since: float | None = None  # monotonic time of the first window held for the posterior
        self.workers: WorkerPool | None = (WorkerPool(predict_worker.init, (self.structure, calibration),
                                                                    predict_worker.ready)
                                           if self.enabled else None)
        steady_timer(self, 0.1, self._poll)

    def teardown(self) -> None:
        if self.workers is not None:
            self.workers.shutdown()

    def _on_window(self, msg: Any) -> None:
        if not self.enabled:
            return
        w = window_from_msg(msg)
        self.windows[w.window_id] = w
        while len(self.windows) > max(1, self.settings.keep_windows):
            self.windows.popitem(last=False)
        if w.is_event:
            self.queue.append(w)

    def _on_request(self, msg: Any) -> None:
        w = self.windows.get(str(msg.data))
        if w is None:
            why = "predictions are off (no measured input)" if not self.enabled else "not among the last windows"
            self.diag.report("warn", f"request for window {msg.data!r}: {why}", "request")
        else:
            self.queue.append(w)

    def _poll(self) -> None:
        if self.future is not None and self.future.done():
            future, self.future = self.future, None
            try:
                pred, row, series = future.result()
            except BrokenProcessPool as exc:
                self.diag.report("error", f"prediction failed: worker process lost ({exc})", "prediction")
                if self.workers is not None:
                    self.workers.restart()
            except Exception as exc:  # a failed prediction must not take the node down
                self.diag.report("error", f"prediction failed: {exc}", "prediction")
            else:
                self.pub.publish(prediction_to_msg(pred))
                fault_point(self.get_name(), "published", delivered(self.pub))  # a test hook: killed after a prediction
                self.done += 1
                if self.settings.output_dir:
                    self.results.append((pred, row, self.future_model, series))
                    self._write_files()
                self.diag.report("ok", f"{pred.window_id}: NRMS floor 4 {row.get('accel_floor4')}, "
                                 f"floor 8 {row.get('accel_floor8')}", "prediction")
            self.diag.publish()
        if self.future is None and self.queue and self.workers is not None:
            posterior = self._posterior_or_wait()
            if posterior is False:
                return
            w = self.queue.popleft()
            self.future = self.workers.submit(predict_worker.run, w, self.config, posterior)
            self.future_model = "updated" if posterior and _posterior_file(posterior).is_file() else "nominal"

    def _write_files(self) -> None:
        """prediction.json + prediction_series.json of the predictions so far (``shm-ros predict``'s layout)."""
        from dataclasses import asdict

        from shm_ros.core.predict import event_json, summary_json
        from shm_ros.core.provenance import stamp_output
        from shm_ros.io import jsonio
        from shm_ros.io.prediction_files import write_series

        preds = [p for p, _, _, _ in self.results]
        models = sorted({m for _, _, m, _ in self.results})
        payload = {"model": models[0] if len(models) == 1 else "mixed",
                   "events": [event_json(p) for p in preds], "table3": [r for _, r, _, _ in self.results],
                   "summary": summary_json(preds), "errors": []}
        cfg = asdict(self.config) | {"structure": self.structure, "posterior": self.settings.posterior}
        try:
            jsonio.dump(stamp_output(payload, cfg, self.config.seed), Path(self.settings.output_dir or ".")
                        / "prediction.json", indent=2)
            write_series(self.settings.output_dir or ".", [t for _, _, _, t in self.results][-MAX_SERIES:])
        except OSError as exc:  # a full disk must not take the node down
            self.diag.report("error", f"cannot write {self.settings.output_dir}: {exc}", "output")

    def _posterior_or_wait(self) -> str | None | Literal[False]:
        """The posterior to predict with, or False while the queued windows still wait for it."""
        path = self.settings.posterior
        wait = float(self.settings.wait_for_posterior_s)
        if not path or self.waiting_since == -1.0:
            return path
        p = _posterior_file(path)
        # the update node writes posterior.json, then samples.npz by rename: both present = complete
        complete = p.is_file() and p.with_name("samples.npz").is_file()
        # with calibration windows the posterior must be their time-domain one: a modal posterior
        # (the time-domain step's prior) plus the model error learnt at the time-domain fits would
        # count the same misfit twice (docs/predict.md)
        if complete and self.settings.calibration_windows and _likelihood(p) != "time":
            if wait <= 0:
                why = f"{p} is not a time-domain posterior (diagnostics.likelihood 'time')"
                self.diag.report("error", f"{why}: predicting with the nominal model", "prediction")
                return None
            complete = False
        if wait <= 0:
            return path
        if complete:
            self.waiting_since = -1.0  # from now on the file is only re-read when it changes
            return path
        now = time.monotonic()
        if self.waiting_since is None:
            self.waiting_since = now
            self.diag.report("ok", f"{len(self.queue)} window(s) wait for the posterior {p}", "prediction")
        if now - self.waiting_since < wait:
            return False
        self.waiting_since = -1.0
        self.diag.report("warn", f"no posterior {p} after {wait:.0f} s: predicting with the nominal model",
                         "prediction")
        return None


def _check_calibration(name: str, paths: tuple[str, ...]) -> None:
    """Calibration windows: two or more readable window files (else the node does not start)."""
    if len(paths) == 1:
        raise ParameterError(f"{name}: parameter 'calibration_windows': give two or more events (one is left "
                             "out at a time)")
    check_window_files(name, "calibration_windows", paths)


def _likelihood(posterior_json: Path) -> str:
    """The likelihood a posterior file was sampled with (``diagnostics.likelihood``; "" if unreadable)."""
    from shm_ros.io import jsonio

    try:
        doc = jsonio.loads(posterior_json.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return ""
    return str((doc.get("diagnostics") or {}).get("likelihood", "")) if isinstance(doc, dict) else ""


def _posterior_file(path: str) -> Path:
    """posterior.json of ``path`` (the file, or its folder, which may not exist yet)."""
    p = Path(path)
    return p / "posterior.json" if p.is_dir() or not p.suffix else p


def make_node(name: str, parameters: dict[str, Any], namespace: str = "") -> PredictNode:
    return PredictNode(name, parameters, namespace)


def main(args: list[str] | None = None) -> int:
    return spin(lambda: PredictNode(), args)


if __name__ == "__main__":
    raise SystemExit(main())
