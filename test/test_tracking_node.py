"""The track node (own process, real DDS): modal estimates in, one TrackedModes per window out,
the same identities and novelty alarms as the offline tracker."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
from ros_helpers.graph import node_process, stop, wait_ready

HERE = Path(__file__).resolve().parent
N, REF, TRAIN, DAMAGE_AT = 160, 20, 60, 0.7

SOURCE = r"""
import json, sys, time
import numpy as np, rclpy
sys.path.insert(0, sys.argv[1])
from test_tracking_core import _campaign
from shm_interfaces.msg import ModalEstimate as EstimateMsg, TrackedModes
from shm_ros.ros.convert import estimate_to_msg
from shm_ros.ros.qos import stream_qos
n = int(sys.argv[2])
est, _, _ = _campaign(11, n=n, damage_at=float(sys.argv[3]), damage=0.02)
rclpy.init(); node = rclpy.create_node("estimates_source")
pub = node.create_publisher(EstimateMsg, "/shm/modal_estimates", stream_qos())
got = {}
node.create_subscription(TrackedModes, "/shm/tracked_modes", lambda m: got.setdefault(m.window_id, m),
                         stream_qos())
end = time.monotonic() + 60
while (pub.get_subscription_count() == 0 or node.count_publishers("/shm/tracked_modes") == 0) \
        and time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.1)
for e in est:
    pub.publish(estimate_to_msg(e))
    rclpy.spin_once(node, timeout_sec=0.005)
end = time.monotonic() + 120
while len(got) < n and time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.1)
rows = [got[e.window_id] for e in est if e.window_id in got]
print(json.dumps({"n": len(rows), "modes": [list(r.mode_numbers) for r in rows[:1]],
                  "freq": [[None if f != f else f for f in r.frequencies_hz] for r in rows],
                  "alarm": [bool(r.novelty_alarm) for r in rows],
                  "shape_len": [len(r.mode_shapes) == len(r.mode_numbers) * len(r.sensor_ids)
                                for r in rows]}))
"""


def test_track_node_publishes_one_row_per_window_like_the_offline_tracker(tmp_path):
    sys.path.insert(0, str(HERE))
    from test_tracking_core import _campaign

    from shm_ros.core.tracking import Tracker, TrackingConfig

    node = node_process("track", {"reference_windows": REF, "training_windows": TRAIN,
                                  "store": str(tmp_path / "track.sqlite")})
    try:
        wait_ready(subscribers={"/shm/modal_estimates": 1}, publishers={"/shm/tracked_modes": 1})
        run = subprocess.run([sys.executable, "-c", SOURCE, str(HERE), str(N), str(DAMAGE_AT)],
                             capture_output=True, text=True, timeout=300)
    finally:
        code, log = stop(node)
    assert run.returncode == 0, run.stdout + run.stderr + log[-3000:]
    got = json.loads(run.stdout.strip().splitlines()[-1])
    assert got["n"] == N, (got["n"], log[-2000:])
    assert got["modes"] == [[1, 2, 3, 4, 5]] and all(got["shape_len"])
    est, _, _ = _campaign(11, n=N, damage_at=DAMAGE_AT, damage=0.02)
    ref = Tracker(TrackingConfig(reference_windows=REF), training_windows=TRAIN)
    rows = [r for e in est for r in ref.add(e)]
    want = np.array([r.frequencies_hz for r in rows])
    have = np.array(got["freq"], dtype=float)
    assert np.allclose(have, want, equal_nan=True)
    assert got["alarm"] == [bool(r.novelty_alarm) for r in rows]
    assert np.mean(got["alarm"][int(DAMAGE_AT * N):]) > 0.9
    assert code == 0, log[-2000:]


def test_a_second_replay_into_the_same_store_republishes_the_stored_rows(tmp_path):
    """The same estimates again (a bag replayed twice, a restart's redelivery) on a store that holds
    them: nothing is tracked twice (the store keeps N windows) and every window's stored row goes
    out again, equal to the first run's, so update and explain downstream get their rows."""
    store = tmp_path / "track.sqlite"
    runs = []
    for _ in range(2):
        node = node_process("track", {"reference_windows": REF, "training_windows": TRAIN, "store": str(store)})
        try:
            wait_ready(subscribers={"/shm/modal_estimates": 1}, publishers={"/shm/tracked_modes": 1})
            run = subprocess.run([sys.executable, "-c", SOURCE, str(HERE), "40", "2.0"],
                                 capture_output=True, text=True, timeout=300)
        finally:
            code, log = stop(node)
        assert run.returncode == 0 and code == 0, run.stdout + run.stderr + log[-3000:]
        runs.append(json.loads(run.stdout.strip().splitlines()[-1]))
    first, second = runs
    assert first["n"] == second["n"] == 40
    assert np.allclose(np.array(second["freq"], float), np.array(first["freq"], float), equal_nan=True)
    assert second["alarm"] == first["alarm"]
    from shm_ros.io.store import TrackStore

    with TrackStore(store, writer=False) as s:
        assert s.count("estimates") == 40 and s.count("rows") == 40
