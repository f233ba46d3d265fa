"""The update node takes the track node's tracked modes over DDS (``TrackedModes``
rows of the core tracker, as the track node publishes them), updates the building model, re-runs
(warm-started) as new windows arrive, and publishes a posterior summary close to the truth
(separate processes). The window-by-window fallback on raw estimates (``input: estimates``) is
exercised by test_update_node_worker.py.

The runs are CI's shorter chains (R-hat < 1.05, ESS >= 300, as in the other updating tests) and
skip the evidence, which nothing here reads: some 3 s of CPU each instead of 30 (the defaults run
to R-hat < 1.01 with ESS near 4,000, and nested sampling takes half). The posterior means agree
with the default runs' to within 0.1 posterior std: the Monte Carlo error of a mean at ESS 300 is
0.06 posterior std, far inside the tolerance of 2 std or 3 %."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from ros_helpers.graph import node_process, stop

ROOT = Path(__file__).resolve().parents[1]
TRUTH = {"k_low": 0.9, "k_mid": 1.05, "k_high": 1.0}

PUBLISH = r"""
import sys, time, json
import numpy as np, rclpy
from rclpy.node import Node
from shm_interfaces.msg import PosteriorSummary
from shm_ros.core.models import build_model
from shm_ros.core.types import ModalEstimate, Mode
from shm_ros.io.structure import load_structure
from shm_ros.core.tracking import Tracker, TrackingConfig
from shm_ros.ros.convert import tracked_row_to_msg
from shm_ros.ros.qos import latched_qos, stream_qos

spec = load_structure(sys.argv[1]); truth = json.loads(sys.argv[2])
sensors = ["f1", "f3", "f6", "f8"]
model = build_model(spec)
# Data: the model at the true factors with 0.5 % frequency and 2 % shape noise per window.
rng = np.random.default_rng(3)
theta = model.theta_vector(truth)
sol = model.modes(theta, 4)
phi = model.sensor_matrix(sensors) @ sol.shapes
rclpy.init(); node = Node("estimates_source")
from shm_interfaces.msg import TrackedModes
pub = node.create_publisher(TrackedModes, "/shm/tracked_modes", stream_qos())
# the track node's core: the first 5 windows establish the modes, then one row per window
tracker = Tracker(TrackingConfig(reference_windows=5), training_windows=10)
sent = 0
got = []
node.create_subscription(PosteriorSummary, "/shm/posterior", got.append, latched_qos())
end = time.monotonic() + 60
while pub.get_subscription_count() == 0 and time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.1)
for w in range(30):
    modes = []
    for k in range(4):
        f = sol.frequencies_hz[k] * (1 + 0.005 * rng.standard_normal())
        s = phi[:, k] * (1 + 0.02 * rng.standard_normal(len(sensors)))
        s = s / s[np.argmax(np.abs(s))]
        modes.append(Mode(frequency_hz=f, damping_ratio=0.02, mode_shape=s))
    t0 = 1_714_521_600_000_000_000 + w * 600 * 10**9
    for row in tracker.add(ModalEstimate(f"w{w}", t0, t0 + 600 * 10**9, sensors, modes)):
        pub.publish(tracked_row_to_msg(row))
        sent += 1
    rclpy.spin_once(node, timeout_sec=0.01)
assert sent == 30, sent
end = time.monotonic() + 240
while not any(m.n_windows == 30 for m in got) and time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.2)
if not got:
    print("no posterior"); sys.exit(1)
m = got[-1]
print(json.dumps({"runs": [g.n_windows for g in got], "n_windows": m.n_windows, "sampler": m.sampler,
                  "params": {p.name: [p.mean, p.std, p.ci95_low, p.ci95_high] for p in m.parameters}}))
"""


def test_update_node_publishes_a_posterior_near_the_truth(tmp_path):
    import json

    structure = ROOT / "examples" / "building.yaml"
    node = node_process("update", {"structure": str(structure), "min_windows": 15,
                                   "min_new_windows": 15, "n_steps": 600, "rhat_target": 1.05,
                                   "ess_target": 300.0, "evidence": False,
                                   "output_dir": str(tmp_path / "out")})
    try:
        run = subprocess.run([sys.executable, "-c", PUBLISH, str(structure), json.dumps(TRUTH)],
                             capture_output=True, text=True, timeout=300)
    finally:
        code, log = stop(node)
    assert run.returncode == 0, run.stdout + run.stderr + log[-3000:]
    result = json.loads(run.stdout.strip().splitlines()[-1])
    # re-run when 15 new windows arrived, warm-started from the first posterior
    assert result["runs"][-2:] == [15, 30], result["runs"]
    assert result["n_windows"] == 30 and result["sampler"] == "emcee"
    for name, true in TRUTH.items():
        mean, std, lo, hi = result["params"][name]
        assert abs(mean - true) <= max(0.03 * true, 2 * std), (name, mean, std, true)
        assert lo < mean < hi
    assert code == 0, log[-2000:]
    doc = json.loads((tmp_path / "out" / "posterior.json").read_text())
    assert doc["schema_version"] and "provenance" in doc and set(doc["parameters"]) == set(TRUTH)
