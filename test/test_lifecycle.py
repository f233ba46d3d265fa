"""Managed nodes: a lifecycle manager drives the graph through the standard lifecycle_msgs services.

One graph, ``shm-ros run --no-autostart --namespace /lc``: ingest and a recorder start unconfigured.

* Its structure file has a bad field: the ingest node's ``configure`` transition fails (the service
  answers ``success: false``, the node stays unconfigured) with that field in the reason (on
  /diagnostics and in the log); the node stays up, and once the file is fixed ``configure`` succeeds.
* Driven by the services the nodes come up (configure, activate: their topics appear, a replayed bag
  comes out as windows in the recorder's bag) and go down (deactivate: no more heartbeats; cleanup:
  their topics are gone and the bag is closed), and come up again (``shm-ros lifecycle up``).

Both points share one graph start (the nodes' start-up is most of the test's time).
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from shm_interfaces.msg import Window
from test_graph_replay import STRUCTURE, _write_bag

from shm_ros.ros.lifecycle import LifecycleClient, bring_down, bring_up
from shm_ros.ros.qos import stream_qos

BAD = STRUCTURE.replace("{id: f2, at: {floor: 2}, direction: x}", "{id: f2, at: {floor: 2}, direction: sideways}")


@pytest.fixture
def probe():
    rclpy.init()
    node = rclpy.create_node("lifecycle_test_probe")
    statuses: list[tuple[str, int, str]] = []
    node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: statuses.extend(
        (s.name, s.level[0] if isinstance(s.level, bytes) else int(s.level), s.message) for s in m.status), 100)
    node.statuses = statuses
    yield node
    node.destroy_node()
    rclpy.shutdown()


def _spin_until(node, pred, timeout: float = 30.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.1)
        value = pred()
        if value:
            return value
    return None


def test_a_bad_field_fails_configure_then_a_manager_brings_the_graph_up_and_down(tmp_path, probe):
    from shm_ros.io.bags import read_messages
    from shm_ros.ros.replay import replay_bag

    structure = tmp_path / "structure.yaml"
    structure.write_text(BAD)
    bag = tmp_path / "recording"
    _write_bag(bag, "imu", np.random.default_rng(3))
    out = tmp_path / "pipeline"
    config = tmp_path / "graph.yaml"
    config.write_text(f"ingest:\n  ros__parameters: {{structure: {structure}, window_s: 10.0}}\n"
                      f"recorder:\n  ros__parameters: {{output: {out}, topics: [shm/windows]}}\n")
    graph = subprocess.Popen([sys.executable, "-m", "shm_ros.cli", "run", str(config), "--no-autostart",
                              "--namespace", "/lc", "--no-restart"], stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True)
    nodes = ["/lc/ingest", "/lc/recorder"]
    try:
        clients = [LifecycleClient(probe, n) for n in nodes]
        assert [c.state(timeout_s=60) for c in clients] == ["unconfigured"] * 2
        assert probe.count_publishers("/lc/shm/windows") == 0  # nothing before configure

        # the bad field fails ingest's configure, with the field and the file in the reason
        assert clients[0].transition("configure") is False
        assert clients[0].state() == "unconfigured"
        reason = _spin_until(probe, lambda: next((m for n, lvl, m in probe.statuses
                                                   if n == "lc/ingest: configure" and lvl == 2), None), 10)
        assert reason and "direction" in reason and str(structure) in reason, probe.statuses
        structure.write_text(STRUCTURE)  # fixed: the same node configures now

        bring_up(probe, nodes)
        assert [c.state() for c in clients] == ["active"] * 2
        assert _spin_until(probe, lambda: probe.count_subscribers("/lc/shm/windows") == 1
                           and probe.count_publishers("/lc/shm/ingest/received") == 1)
        heartbeat = _spin_until(probe, lambda: any(n == "lc/ingest: status" for n, _, _ in probe.statuses))
        assert heartbeat, probe.statuses
        seen: set[str] = set()
        probe.create_subscription(Window, "/lc/shm/windows", lambda m: seen.add(m.window_id), stream_qos())
        result = replay_bag(bag, wait_s=30.0, namespace="/lc")
        assert result.published > 0 and result.lost == 0
        assert _spin_until(probe, lambda: len(seen) == 6), seen  # two 25-s bursts in 10-s windows
        time.sleep(0.5)

        bring_down(probe, nodes)
        assert [c.state() for c in clients] == ["unconfigured"] * 2
        probe.statuses.clear()
        gone = _spin_until(probe, lambda: probe.count_publishers("/lc/shm/windows") == 0
                           and probe.count_publishers("/lc/shm/ingest/received") == 0
                           and probe.count_subscribers("/lc/shm/windows") == 1, 10)  # the probe's own
        assert gone, "cleanup left the node's topics in the graph"
        _spin_until(probe, lambda: False, 3.0)
        assert not [n for n, _, _ in probe.statuses if n.startswith("lc/")], probe.statuses  # silent when down
        windows = [m for m in read_messages(out) if m.topic == "/lc/shm/windows"]  # closed by cleanup
        assert len(windows) == 6, len(windows)  # every window reached the recorder's bag

        # and up again, by the command line's manager (ingest: the recorder's bag is written)
        up = subprocess.run([sys.executable, "-m", "shm_ros.cli", "lifecycle", "up", "ingest", "--namespace", "/lc"],
                            capture_output=True, text=True, timeout=120)
        assert up.returncode == 0 and "/lc/ingest: active" in up.stdout, up.stdout + up.stderr
        assert clients[0].state() == "active"
        assert _spin_until(probe, lambda: probe.count_publishers("/lc/shm/windows") == 1)
    finally:
        graph.send_signal(signal.SIGINT)
        text, _ = graph.communicate(timeout=60)
    assert graph.returncode == 0, text[-3000:]
    assert "direction" in text  # the reason is in the node's log too
