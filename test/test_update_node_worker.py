"""The update node keeps receiving while it samples (own process, real DDS).

A run is made long by its own parameters (an ESS target no chain reaches, so it runs to
``max_steps``: some 7 s of CPU, against milliseconds for the three round trips of estimate and
progress report it must outlast; on a loaded machine the run slows down as well). Estimates sent
during the run are received at once (the node's progress diagnostic counts them and says it is
still sampling the same run); when the run is done its posterior is published and the queued run
starts with every window received by then; stopping the node in the middle of a run ends it
cleanly. The node runs without a track node here (``input: estimates``: raw modal estimates,
each window paired with the model).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from ros_helpers.graph import node_process, stop

ROOT = Path(__file__).resolve().parents[1]
FIRST, DURING = 3, 3

CLIENT = r"""
import json, sys, time
import numpy as np, rclpy
from diagnostic_msgs.msg import DiagnosticArray
from shm_interfaces.msg import ModalEstimate as EstimateMsg, PosteriorSummary
from shm_ros.core.models import build_model
from shm_ros.core.types import ModalEstimate, Mode
from shm_ros.io.structure import load_structure
from shm_ros.ros.convert import estimate_to_msg
from shm_ros.ros.qos import latched_qos, pipeline_qos, stream_qos

first, during = int(sys.argv[2]), int(sys.argv[3])
spec = load_structure(sys.argv[1])
model = build_model(spec)
sensors = ["f1", "f3", "f6", "f8"]
sol = model.modes(model.theta_vector({"k_low": 0.9, "k_mid": 1.05, "k_high": 1.0}), 4)
phi = model.sensor_matrix(sensors) @ sol.shapes
rng = np.random.default_rng(5)

def estimate(w):
    modes = []
    for k in range(4):
        s = phi[:, k] * (1 + 0.02 * rng.standard_normal(len(sensors)))
        modes.append(Mode(frequency_hz=sol.frequencies_hz[k] * (1 + 0.005 * rng.standard_normal()),
                          damping_ratio=0.02, mode_shape=s / s[np.argmax(np.abs(s))]))
    t0 = 1_714_521_600_000_000_000 + w * 600 * 10**9
    return estimate_to_msg(ModalEstimate(f"w{w}", t0, t0 + 600 * 10**9, sensors, modes))

rclpy.init()
node = rclpy.create_node("update_worker_probe")
pub = node.create_publisher(EstimateMsg, "/shm/modal_estimates", stream_qos())
events = []  # (what, payload) in the order the probe saw them
progress = []
def on_diag(msg):
    for s in msg.status:
        if s.name.endswith(": progress"):
            v = {kv.key: kv.value for kv in s.values}
            progress.append(v)
            events.append(("progress", v))
node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, pipeline_qos())
posteriors = []
def on_posterior(m):
    posteriors.append(m.n_windows)
    events.append(("posterior", m.n_windows))
node.create_subscription(PosteriorSummary, "/shm/posterior", on_posterior, latched_qos())

def wait(pred, what, timeout=300.0):
    end = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > end:
            print(json.dumps({"timeout": what, "events": events})); sys.exit(1)
        rclpy.spin_once(node, timeout_sec=0.1)

wait(lambda: pub.get_subscription_count() > 0 and node.count_publishers("/diagnostics") > 0,
     "node up")
for w in range(first):
    pub.publish(estimate(w))
wait(lambda: any(p["sampling"] == "true" and p["run_windows"] == str(first) for p in progress),
     "first run started")
started = next(p["started_at"] for p in progress if p["sampling"] == "true")
for w in range(first, first + during):
    pub.publish(estimate(w))
    n = w + 1
    # the node takes it while the first run goes on
    wait(lambda: any(p["received"] == str(n) for p in progress), f"estimate {n} received")
wait(lambda: posteriors, "first posterior")
wait(lambda: any(p["sampling"] == "true" and p["started_at"] != started for p in progress),
     "queued run started")
print(json.dumps({"started": started, "events": events}))
"""


def test_update_node_receives_while_sampling_and_queues_the_next_run(tmp_path):
    node = node_process("update", {
        "structure": str(ROOT / "examples" / "building.yaml"), "input": "estimates", "min_windows": FIRST,
        "min_new_windows": 1, "evidence": False, "n_steps": 2000, "max_steps": 2000,
        "ess_target": 1.0e12})
    try:
        run = subprocess.run([sys.executable, "-c", CLIENT, str(ROOT / "examples" / "building.yaml"),
                              str(FIRST), str(DURING)], capture_output=True, text=True, timeout=600)
    finally:
        code, log = stop(node)  # in the middle of the queued run
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:] + log[-3000:]
    result = json.loads(run.stdout.strip().splitlines()[-1])
    events = result["events"]
    first_posterior = next(i for i, (what, _) in enumerate(events) if what == "posterior")
    # every estimate sent during the run was taken, by the node's own account during that run
    for n in range(FIRST + 1, FIRST + DURING + 1):
        seen = [i for i, (what, p) in enumerate(events)
                if what == "progress" and p["received"] == str(n)]
        assert seen, (n, events)
        status = events[seen[0]][1]
        assert status["sampling"] == "true" and status["started_at"] == result["started"], status
        assert status["run_windows"] == str(FIRST), status
        assert seen[0] < first_posterior, events
    assert events[first_posterior][1] == FIRST
    # the queued run took every window received by then
    nxt = [p for what, p in events[first_posterior:] if what == "progress" and p["sampling"] == "true"]
    assert nxt and nxt[0]["run_windows"] == str(FIRST + DURING), events
    assert code == 0, log[-3000:]
