"""The predict node over DDS: event windows in, one ResponsePrediction per event out, equal (same
seed) to the numbers of ``shm-ros predict`` on the same windows within 1e-9 (separate processes)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import yaml
from predict_synth import simulate_quakes
from ros_helpers.graph import node_process, stop

from shm_ros.cli import main
from shm_ros.io.window_files import save_window

PUBLISH = r"""
import sys, time, json
import numpy as np, rclpy
from rclpy.node import Node
from shm_interfaces.msg import ResponsePrediction, Window as WindowMsg
from shm_ros.io.window_files import load_window
from shm_ros.ros.convert import window_to_msg
from shm_ros.ros.qos import stream_qos

files = sys.argv[1:]
rclpy.init(); node = Node("windows_source")
pub = node.create_publisher(WindowMsg, "/shm/windows", stream_qos())
got = []
node.create_subscription(ResponsePrediction, "/shm/prediction", got.append, stream_qos())
end = time.monotonic() + 60
while (pub.get_subscription_count() == 0 or node.count_publishers("/shm/prediction") == 0) \
        and time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.1)
for f in files:
    pub.publish(window_to_msg(load_window(f)))
    rclpy.spin_once(node, timeout_sec=0.05)
end = time.monotonic() + 240
while len(got) < len(files) and time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.2)
print(json.dumps([{"id": m.window_id, "names": list(m.channel_names), "nrms": list(m.nrms_pct),
                   "n": m.n_samples, "mean": list(m.predicted_mean[:50]), "std": list(m.predicted_std[:50])}
                  for m in got]))
"""


def test_predict_node_matches_cli(tmp_path):
    q = simulate_quakes(5, 2, duration_s=30.0, fs=40.0)
    s_path = tmp_path / "s.yaml"
    s_path.write_text(yaml.safe_dump(q.structure))
    files = []
    for i, w in enumerate(q.windows):
        assert w.is_event
        files.append(str(tmp_path / f"w{i}.npz"))
        save_window(files[-1], w)
    assert main(["predict", "--structure", str(s_path), "--windows", *files, "--out", str(tmp_path / "cli"),
                 "--no-plots", "--n-draws", "20", "--seed", "3"]) == 0
    cli = json.loads((tmp_path / "cli" / "prediction.json").read_text())

    node = node_process("predict", {"structure": str(s_path), "n_draws": 20, "seed": 3})
    try:
        run = subprocess.run([sys.executable, "-c", PUBLISH, *files], capture_output=True, text=True, timeout=300)
    finally:
        _, log = stop(node)
    assert run.returncode == 0, run.stdout + run.stderr + log[-3000:]
    got = json.loads(run.stdout.strip().splitlines()[-1])
    assert sorted(m["id"] for m in got) == sorted(w.window_id for w in q.windows), log[-3000:]
    for m in got:
        ev = next(e for e in cli["events"] if e["window_id"] == m["id"])
        by = {c["name"]: c for c in ev["channels"]}
        assert m["names"] == [c["name"] for c in ev["channels"]]
        for name, v in zip(m["names"], m["nrms"], strict=True):
            if by[name]["measured"]:
                assert abs(v - by[name]["nrms_pct"]) < 1e-9
            else:
                assert np.isnan(v)
        assert m["n"] == int(round(30.0 * 40.0))
