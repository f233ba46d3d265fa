"""Replay a bag through a freshly started node graph and collect what the graph published.

Used by ``shm-ros example`` and by end-to-end tests: the nodes are real processes started by the
:class:`~shm_ros.ros.supervisor.Supervisor`, data crosses DDS, the stages overlap as data flows
(identify works on a window while track and update work on earlier ones), and the recorder node's
output bag is what comes back.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from shm_ros.core.progress import Progress
from shm_ros.core.types import ModalEstimate, Window
from shm_ros.errors import ShmError
from shm_ros.ros.graph_config import GraphConfig, NodeSpec, normal_namespace
from shm_ros.ros.replay import ReplayResult
from shm_ros.ros.supervisor import Supervisor


@dataclass
class PipelineRecord:
    """What the recorder node wrote: windows, modal estimates, tracked-mode rows (message fields
    as a dict per window), posterior summaries (one per update run) and non-OK diagnostics."""

    windows: list[Window] = field(default_factory=list)
    estimates: list[ModalEstimate] = field(default_factory=list)
    tracked: list[dict[str, Any]] = field(default_factory=list)
    posteriors: list[dict[str, Any]] = field(default_factory=list)
    diagnostics: list[str] = field(default_factory=list)
    # every diagnostic status: level (0 OK .. 3 STALE), source (the status name), message, values
    diagnostic_rows: list[dict[str, Any]] = field(default_factory=list)
    # ResponsePrediction messages: window_id, channel_names, measured, nrms_pct, n_samples,
    # predicted_mean and predicted_std (row-major samples x channels)
    predictions: list[dict[str, Any]] = field(default_factory=list)
    # Verdict messages: summary, missing physics (name, where, form, log_evidence_gain), fit figures
    verdicts: list[dict[str, Any]] = field(default_factory=list)


@dataclass
class GraphRun:
    replay: ReplayResult
    windows: list[Window] = field(default_factory=list)
    estimates: list[ModalEstimate] = field(default_factory=list)
    diagnostics: list[str] = field(default_factory=list)
    output_bag: Path | None = None
    node_exit_code: int = 0
    tracked: list[dict[str, Any]] = field(default_factory=list)
    posteriors: list[dict[str, Any]] = field(default_factory=list)
    wall_s: float = 0.0
    diagnostic_rows: list[dict[str, Any]] = field(default_factory=list)
    predictions: list[dict[str, Any]] = field(default_factory=list)
    verdicts: list[dict[str, Any]] = field(default_factory=list)


def verdict_record(msg: Any) -> dict[str, Any]:
    """A ``Verdict`` message as a dict (the fields a reader of the run needs)."""
    return {"summary": msg.summary, "mismatch_modes": list(msg.mismatch_modes),
            "missing_physics": [{"name": m.name, "where": m.where, "form": m.form,
                                 "parameters": dict(zip(m.parameter_names, m.parameter_values, strict=False)),
                                 "log_evidence_gain": m.log_evidence_gain,
                                 "form_fits": m.form_fits if m.form_fits_known else None,
                                 "downgraded_by": m.downgraded_by or None} for m in msg.missing_physics],
            "before_frequency_rmse_pct": msg.before_frequency_rmse_pct,
            "after_frequency_rmse_pct": msg.after_frequency_rmse_pct, "kind": msg.kind,
            "before_nrms_pct": msg.before_nrms_pct, "after_nrms_pct": msg.after_nrms_pct,
            "held_out_before_nrms_pct": msg.held_out_before_nrms_pct,
            "held_out_after_nrms_pct": msg.held_out_after_nrms_pct,
            "whiteness_modes": list(msg.whiteness_modes), "lag1_before": list(msg.lag1_before),
            "lag1_after": list(msg.lag1_after), "still_structured_modes": list(msg.still_structured_modes),
            "status": msg.status, "fit_ratio": msg.fit_ratio,
            "model_fits": msg.model_fits if msg.model_fits_known else None}


def _level(status: Any) -> int:
    """A DiagnosticStatus level as an int (the bag's decoder gives a byte)."""
    level = status.level
    return int.from_bytes(level, "little") if isinstance(level, bytes) else int(level)


def read_pipeline_bag(path: Path, namespace: str = "") -> PipelineRecord:
    """Everything the recorder node of the graph in ``namespace`` recorded, decoded (of the global
    ``/diagnostics``, the statuses of that graph's nodes)."""
    from rclpy.serialization import deserialize_message

    from shm_ros.io.bags import read_messages
    from shm_ros.ros import topics
    from shm_ros.ros.convert import estimate_from_msg, window_from_msg
    from shm_ros.ros.diagnostics import status_prefix

    rec = PipelineRecord()
    mine = status_prefix(namespace)
    for m in read_messages(path):
        cls = topics.message_class(m.msgtype)
        msg: Any = deserialize_message(m.data, cls)
        topic = topics.relative(m.topic, namespace)
        if topic == topics.WINDOWS:
            rec.windows.append(window_from_msg(msg))
        elif topic == topics.MODAL_ESTIMATES:
            rec.estimates.append(estimate_from_msg(msg))
        elif topic == topics.TRACKED_MODES:
            rec.tracked.append({"window_id": msg.window_id, "mode_numbers": list(msg.mode_numbers),
                                "frequencies_hz": list(msg.frequencies_hz),
                                "damping_ratios": list(msg.damping_ratios)})
        elif topic == topics.POSTERIOR:
            rec.posteriors.append({"n_windows": int(msg.n_windows), "converged": bool(msg.converged),
                                   "parameters": {p.name: {"mean": p.mean, "std": p.std} for p in msg.parameters}})
        elif topic == topics.PREDICTION:
            rec.predictions.append({"window_id": msg.window_id, "channel_names": list(msg.channel_names),
                                    "measured": list(msg.measured), "nrms_pct": list(msg.nrms_pct),
                                    "n_samples": int(msg.n_samples), "predicted_mean": list(msg.predicted_mean),
                                    "predicted_std": list(msg.predicted_std)})
        elif topic == topics.VERDICT:
            rec.verdicts.append(verdict_record(msg))
        elif topic == topics.DIAGNOSTICS:
            statuses = [st for st in msg.status if st.name.startswith(mine) and (
                mine or "/" not in st.name.split(":")[0])]  # at the root: not a namespaced graph's
            rec.diagnostics += [f"{s.name}: {s.message}" for s in statuses if _level(s) != 0]
            for st in statuses:
                values = {kv.key: kv.value for kv in st.values}
                rec.diagnostic_rows.append({"level": _level(st), "source": st.name, "message": st.message,
                    "code": values.get("code", st.hardware_id or ""), "values": values})
    return rec


def analysis_nodes(structure: str | Path, window_s: float, *, identify: dict | None = None,
                   track: dict | None = None, update: dict | None = None,
                   predict: dict | None = None, explain: dict | None = None) -> list[NodeSpec]:
    """ingest + identify, and track / update / predict / explain when their parameters are given."""
    nodes = [NodeSpec("ingest", "ingest", {"structure": str(structure), "window_s": float(window_s)}),
             NodeSpec("identify", "identify", {"structure": str(structure), **(identify or {})})]
    if track is not None:
        nodes.append(NodeSpec("track", "track", dict(track)))
    if update is not None:
        nodes.append(NodeSpec("update", "update", {"structure": str(structure), **update}))
    if predict is not None:
        nodes.append(NodeSpec("predict", "predict", {"structure": str(structure), **predict}))
    if explain is not None:
        nodes.append(NodeSpec("explain", "explain", {"structure": str(structure), **explain}))
    return nodes


def replay_through_graph(bag: str | Path, structure: str | Path, workdir: str | Path, *,
                         window_s: float, expected_windows: int | None = None,
                         identify: dict | None = None, track: dict | None = None,
                         update: dict | None = None, predict: dict | None = None,
                         explain: dict | None = None, expected_predictions: int | None = None,
                         expected_events: int | None = None, timeout_s: float = 600.0,
                         log: Callable[[str], None] = print, namespace: str = "",
                         single_process: bool = False, posterior_windows: int | None = None) -> GraphRun:
    """Start the analysis nodes and a recorder as processes, replay ``bag``, wait until every
    window is identified (and tracked, and in a posterior - or in one of ``posterior_windows``
    windows when the update node is set to run on the first windows only -, and
    ``expected_predictions`` predicted, when those nodes run, and explained by the explain node: every
    window, or with ``expected_events`` that many event windows in the time domain), stop, collect."""
    nodes = analysis_nodes(structure, window_s, identify=identify, track=track, update=update, predict=predict,
                           explain=explain)
    return run_graph(bag, nodes, workdir, expected_windows=expected_windows,
                     expected_predictions=expected_predictions, expected_events=expected_events,
                     timeout_s=timeout_s, log=log, namespace=namespace, single_process=single_process,
                     posterior_windows=posterior_windows)


def _explains_events(node: NodeSpec) -> bool:
    """Whether an explain node subscribes to the windows (its ``events`` parameter, docs/parameters.md)."""
    if node.kind != "explain":
        return False
    from shm_ros.io.structure import load_structure
    from shm_ros.ros.explain_node import explains_events

    try:
        has_input = bool(load_structure(node.parameters["structure"]).input_sensor_ids())
    except ShmError:  # the node itself reports a bad file
        has_input = False
    return explains_events(str(node.parameters.get("events", "auto")), has_input)


def for_replay(nodes: list[NodeSpec]) -> list[NodeSpec]:
    """The nodes with ingest subscribing to the recording reliably unless told otherwise: the replay
    publishes reliably and paces itself by ingest's acknowledgements, so nothing is lost, also between
    hosts over UDP (where best-effort samples can drop on a loaded host)."""
    return [NodeSpec(n.name, n.kind, {"reliable_input": True, **n.parameters}) if n.kind == "ingest" else n
            for n in nodes]


def run_graph(bag: str | Path, nodes: list[NodeSpec], workdir: str | Path, *,
              expected_windows: int | None = None, expected_predictions: int | None = None,
              expected_events: int | None = None, timeout_s: float = 600.0,
              log: Callable[[str], None] = print, namespace: str = "", single_process: bool = False,
              posterior_windows: int | None = None) -> GraphRun:
    """Start ``nodes`` and a recorder (in ``namespace``, e.g. ``/bridge_a``, when given; all in one
    process with ``single_process``), replay ``bag`` into that namespace, wait until the graph is
    done with it (see :func:`replay_through_graph`), stop, collect."""
    import threading

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from shm_ros.ros import topics
    from shm_ros.ros.diagnostics import status_prefix
    from shm_ros.ros.qos import latched_qos, pipeline_qos, stream_qos
    from shm_ros.ros.replay import replay_bag

    nodes = for_replay(nodes)
    kinds = {n.kind for n in nodes}
    workdir = Path(workdir)
    out_bag = workdir / "pipeline_bag"
    if out_bag.exists():
        shutil.rmtree(out_bag)
    recorder = NodeSpec("recorder", "recorder", {"output": str(out_bag)})
    namespace = normal_namespace(namespace)
    sup = Supervisor(GraphConfig(nodes=[*nodes, recorder], restart=False, namespace=namespace,
                                 mode="single" if single_process else "processes"), log=log)
    t0 = time.monotonic()
    sup.start_all()
    rclpy.init()
    try:
        # Count results as they arrive, so we know when the graph is done with the recording.
        watcher = Node("shm_graph_watch", namespace=namespace or None)
        mine = status_prefix(namespace)
        seen: dict[str, set[str]] = {"estimates": set(), "tracked": set(), "predicted": set()}
        posterior_seen = [0]
        explained_windows = [0]
        explained_events = [0]

        def on_posterior(m: Any) -> None:
            posterior_seen[0] = max(posterior_seen[0], int(m.n_windows))

        watcher.create_subscription(topics.message_class(topics.TYPES[topics.MODAL_ESTIMATES]),
                                    topics.MODAL_ESTIMATES, lambda m: seen["estimates"].add(m.window_id),
                                    pipeline_qos())
        watcher.create_subscription(topics.message_class(topics.TYPES[topics.TRACKED_MODES]),
                                    topics.TRACKED_MODES, lambda m: seen["tracked"].add(m.window_id),
                                    pipeline_qos())
        watcher.create_subscription(topics.message_class(topics.TYPES[topics.POSTERIOR]),
                                    topics.POSTERIOR, on_posterior, latched_qos())
        if "predict" in kinds:
            watcher.create_subscription(topics.message_class(topics.TYPES[topics.PREDICTION]),
                                        topics.PREDICTION, lambda m: seen["predicted"].add(m.window_id),
                                        stream_qos())
        window_readers = [0]

        def on_diagnostics(m: Any) -> None:
            for st in m.status:
                values = {kv.key: kv.value for kv in st.values}
                if st.name == f"{mine}ingest: status":
                    window_readers[0] = int(values.get("window_readers", 0))
                elif st.name == f"{mine}explain: verdict" and "windows" in values:
                    explained_windows[0] = max(explained_windows[0], int(values["windows"]))
                elif st.name == f"{mine}explain: events verdict" and "events" in values:
                    explained_events[0] = max(explained_events[0], int(values["events"]))

        from diagnostic_msgs.msg import DiagnosticArray

        watcher.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, on_diagnostics, pipeline_qos())
        # Every node must be up before the first message: windows are not kept for late joiners.
        # The graph as this process sees it is not enough on a busy machine: ingest's own window
        # publisher must have matched identify and the recorder (its status says so).
        # the update node reads the track node's rows unless its input is the estimates
        raw_update = any(n.kind == "update" and n.parameters.get("input") == "estimates" for n in nodes)
        tracked_update = "update" in kinds and not raw_update
        estimate_readers = 1 + ("track" in kinds) + raw_update  # + the watcher's own
        # identify, the recorder, predict, explain (event series)
        win_readers = 2 + ("predict" in kinds) + any(_explains_events(n) for n in nodes)
        ready_by = time.monotonic() + 120.0
        while time.monotonic() < ready_by and not (
                window_readers[0] >= win_readers
                and watcher.count_subscribers(topics.WINDOWS) >= win_readers
                and watcher.count_publishers(topics.MODAL_ESTIMATES) >= 1
                and watcher.count_publishers(topics.INGEST_RECEIVED) >= 1
                and watcher.count_subscribers(topics.MODAL_ESTIMATES) >= estimate_readers + 1
                and ("track" not in kinds or watcher.count_publishers(topics.TRACKED_MODES) >= 1)
                and (not (tracked_update or "explain" in kinds)  # + recorder, watcher
                     or watcher.count_subscribers(topics.TRACKED_MODES) >= 2 + tracked_update + ("explain" in kinds))
                and ("update" not in kinds or watcher.count_publishers(topics.POSTERIOR) >= 1)
                and ("predict" not in kinds or watcher.count_publishers(topics.PREDICTION) >= 1)):
            rclpy.spin_once(watcher, timeout_sec=0.2)
        # From here the watcher spins in a thread of its own: a flat-out replay takes minutes, and a
        # watcher not taking its messages meanwhile loses all but the last PIPELINE_DEPTH of them
        # (keep-last history), so the graph never looked done on a long campaign.
        executor = SingleThreadedExecutor()
        executor.add_node(watcher)
        spinner = threading.Thread(target=executor.spin, name="graph-watch", daemon=True)
        spinner.start()
        result = replay_bag(bag, rate=0.0, wait_s=60.0, progress=True, namespace=namespace)
        log(f"replayed {result.published} messages, lost {result.lost}")

        def done() -> bool:
            if expected_windows is None:
                return False
            return (len(seen["estimates"]) >= expected_windows
                    and ("track" not in kinds or len(seen["tracked"]) >= expected_windows)
                    and ("update" not in kinds or posterior_seen[0] >= (posterior_windows or expected_windows))
                    and ("predict" not in kinds or len(seen["predicted"]) >= (expected_predictions or 0))
                    and ("explain" not in kinds or (explained_windows[0] >= expected_windows if expected_events is None
                                                    else explained_events[0] >= expected_events)))

        bar = Progress("graph", every_s=5.0)
        end = time.monotonic() + timeout_s
        quiet_since, last = time.monotonic(), 0
        while time.monotonic() < end and not done():
            time.sleep(0.2)
            if expected_windows:
                bar(len(seen["estimates"]), expected_windows)
            dead = [name for name, p in sup.procs.items() if p.poll() is not None]
            if dead:
                log(f"node(s) {dead} exited before the graph was done with the recording")
                break
            if len(seen["estimates"]) != last:
                last, quiet_since = len(seen["estimates"]), time.monotonic()
            if expected_windows is None and last and time.monotonic() - quiet_since > 20:
                break
        log(f"identified {len(seen['estimates'])} windows"
            + (f", tracked {len(seen['tracked'])}" if "track" in kinds else "")
            + (f", posterior from {posterior_seen[0]} windows" if "update" in kinds else "")
            + (f", predicted {len(seen['predicted'])}" if "predict" in kinds else "")
            + (f", explained {explained_windows[0]}" if "explain" in kinds else "")
            + (f", {explained_events[0]} events explained" if expected_events is not None else ""))
        time.sleep(1.0)  # let the recorder write the last messages
        executor.shutdown()
        spinner.join(timeout=10.0)
        watcher.destroy_node()
    finally:
        rclpy.try_shutdown()
        code = sup.stop_all()
        for why in sup.lost.values():  # which node made the run's exit code 1, and why
            log(f"[supervisor] {why}")
    rec = read_pipeline_bag(out_bag, namespace)
    return GraphRun(result, rec.windows, rec.estimates, rec.diagnostics, out_bag, code, rec.tracked,
                    rec.posteriors, time.monotonic() - t0, rec.diagnostic_rows, rec.predictions, rec.verdicts)
