"""Replay a bag through a freshly started node graph and collect what the graph published.

Used by ``shm-ros example`` and by end-to-end tests: the nodes are real processes started by the
:class:`~shm_ros.ros.supervisor.Supervisor`, data crosses DDS, and the recorder node's output bag is
what comes back.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from shm_ros.core.types import ModalEstimate, Window
from shm_ros.ros.replay import ReplayResult
from shm_ros.ros.supervisor import GraphConfig, NodeSpec, Supervisor


@dataclass
class GraphRun:
    replay: ReplayResult
    windows: list[Window] = field(default_factory=list)
    estimates: list[ModalEstimate] = field(default_factory=list)
    diagnostics: list[str] = field(default_factory=list)
    output_bag: Path | None = None
    node_exit_code: int = 0


def read_pipeline_bag(path: Path) -> tuple[list[Window], list[ModalEstimate], list[str]]:
    """Windows, modal estimates and non-OK diagnostics recorded by the recorder node."""
    from rclpy.serialization import deserialize_message

    from shm_ros.io.bags import read_messages
    from shm_ros.ros import topics
    from shm_ros.ros.convert import estimate_from_msg, window_from_msg

    windows, estimates, diags = [], [], []
    for m in read_messages(path):
        cls = topics.message_class(m.msgtype)
        msg: Any = deserialize_message(m.data, cls)
        if m.topic == topics.WINDOWS:
            windows.append(window_from_msg(msg))
        elif m.topic == topics.MODAL_ESTIMATES:
            estimates.append(estimate_from_msg(msg))
        elif m.topic == topics.DIAGNOSTICS:
            diags += [f"{s.name}: {s.message}" for s in msg.status if s.level != 0]
    return windows, estimates, diags


def replay_through_graph(bag: str | Path, structure: str | Path, workdir: str | Path, *,
                         window_s: float, expected_windows: int | None = None,
                         identify: dict | None = None, timeout_s: float = 600.0,
                         log=print) -> GraphRun:
    """Start ingest + identify + recorder as processes, replay ``bag``, wait, stop, collect."""
    import rclpy
    from rclpy.node import Node

    from shm_ros.ros import topics
    from shm_ros.ros.qos import pipeline_qos
    from shm_ros.ros.replay import replay_bag

    workdir = Path(workdir)
    out_bag = workdir / "pipeline_bag"
    if out_bag.exists():
        import shutil

        shutil.rmtree(out_bag)
    config = GraphConfig(nodes=[
        NodeSpec("ingest", "ingest", {"structure": str(structure), "window_s": float(window_s)}),
        NodeSpec("identify", "identify", dict(identify or {})),
        NodeSpec("recorder", "recorder", {"output": str(out_bag)}),
    ], restart=False)
    sup = Supervisor(config, log=log)
    sup.start_all()
    rclpy.init()
    try:
        # Count estimates as they arrive, so we know when the graph is done with the recording.
        watcher = Node("shm_example_watch")
        seen: list[str] = []
        watcher.create_subscription(topics.message_class(topics.TYPES[topics.MODAL_ESTIMATES]),
                                    topics.MODAL_ESTIMATES, lambda m: seen.append(m.window_id),
                                    pipeline_qos())
        # Every node must be up before the first message: windows are not kept for late joiners.
        ready_by = time.monotonic() + 120.0
        while time.monotonic() < ready_by and not (
                watcher.count_subscribers(topics.WINDOWS) >= 2
                and watcher.count_publishers(topics.MODAL_ESTIMATES) >= 1
                and watcher.count_publishers(topics.INGEST_RECEIVED) >= 1):
            rclpy.spin_once(watcher, timeout_sec=0.2)
        result = replay_bag(bag, rate=0.0, wait_s=60.0, progress=True)
        log(f"replayed {result.published} messages, lost {result.lost}")
        windows_seen: list[str] = []
        watcher.create_subscription(topics.message_class(topics.TYPES[topics.WINDOWS]),
                                    topics.WINDOWS, lambda m: windows_seen.append(m.window_id),
                                    pipeline_qos())
        end = time.monotonic() + timeout_s
        quiet_since = time.monotonic()
        last = 0
        while time.monotonic() < end:
            rclpy.spin_once(watcher, timeout_sec=0.2)
            if expected_windows is not None and len(seen) >= expected_windows:
                break
            dead = [name for name, p in sup.procs.items() if p.poll() is not None]
            if dead:
                log(f"node(s) {dead} exited before every window was identified")
                break
            if len(seen) != last:
                last, quiet_since = len(seen), time.monotonic()
            if expected_windows is None and seen and time.monotonic() - quiet_since > 20:
                break
        time.sleep(1.0)  # let the recorder write the last estimate
        watcher.destroy_node()
    finally:
        rclpy.try_shutdown()
        code = sup.stop_all()
    windows, estimates, diags = read_pipeline_bag(out_bag)
    return GraphRun(result, windows, estimates, diags, out_bag, code)
