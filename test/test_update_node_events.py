"""The update node's time-domain step on recorded events (``calibration_windows``), its own process
over DDS: given modal estimates (``input: estimates``) it writes its modal posterior, then, with that
posterior as the prior, calibrates on two simulated earthquakes' window files in the time domain and
writes that posterior to ``<output_dir>/time``: likelihood ``time``, per parameter the prior
normal(mean, std) of the modal posterior, the modal posterior left as it was. The predict node, given
calibration windows, tells the two apart by that likelihood (it takes only a time-domain one)."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

from ros_helpers.graph import node_process, stop

from shm_ros.cli import main
from shm_ros.io.recording import windows_from_bag
from shm_ros.io.structure import load_structure
from shm_ros.io.window_files import save_window
from shm_ros.ros.predict_node import _likelihood

ROOT = Path(__file__).resolve().parents[1]
WINDOW_S, N_WINDOWS = 20.0, 4

PROBE = r"""
import sys, time
import numpy as np, rclpy
from shm_interfaces.msg import ModalEstimate as EstimateMsg
from shm_ros.core.models import build_model
from shm_ros.core.types import ModalEstimate, Mode
from shm_ros.io.structure import load_structure
from shm_ros.ros.convert import estimate_to_msg
from shm_ros.ros.qos import stream_qos

spec = load_structure(sys.argv[1])
model = build_model(spec)
sensors = model.observed_sensors(spec.sensor_ids)
sol = model.modes(model.theta_vector({n: 0.95 for n in model.parameter_names}), 3)
phi = model.sensor_matrix(sensors) @ sol.shapes
rng = np.random.default_rng(5)
rclpy.init()
node = rclpy.create_node("update_events_probe")
pub = node.create_publisher(EstimateMsg, "/shm/modal_estimates", stream_qos())
end = time.monotonic() + 60.0
while pub.get_subscription_count() == 0 and time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.1)
for w in range(int(sys.argv[2])):
    modes = []
    for k in range(3):
        s = phi[:, k] * (1 + 0.02 * rng.standard_normal(len(sensors)))
        modes.append(Mode(frequency_hz=sol.frequencies_hz[k] * (1 + 0.005 * rng.standard_normal()),
                          damping_ratio=0.02, mode_shape=s / s[np.argmax(np.abs(s))]))
    t0 = 1_714_521_600_000_000_000 + w * 600 * 10**9
    pub.publish(estimate_to_msg(ModalEstimate(f"w{w}", t0, t0 + 600 * 10**9, list(sensors), modes)))
    time.sleep(0.05)
time.sleep(1.0)
"""


def _wait_file(path, proc, timeout) -> bool:
    end = time.monotonic() + timeout
    while not path.is_file():
        if time.monotonic() > end or proc.poll() is not None:
            return False
        time.sleep(0.5)
    return True


def test_update_node_calibrates_on_events_with_the_modal_prior(tmp_path):
    d = tmp_path / "quake"
    assert main(["simulate", "building-earthquake", "--out", str(d), "--windows", str(N_WINDOWS), "--window-s",
                 str(WINDOW_S), "--quiet", "--seed", "3"]) == 0
    structure = d / "structure.yaml"
    windows, _ = windows_from_bag(d / "bag", load_structure(structure), WINDOW_S)
    events = [w for w in windows if w.is_event][:2]
    assert len(events) == 2
    cal = [str(tmp_path / f"cal{i}.npz") for i in range(2)]
    for p, w in zip(cal, events, strict=True):
        save_window(p, w)
    out = tmp_path / "update"
    node = node_process("update", {
        "structure": str(structure), "input": "estimates", "min_windows": 5, "min_new_windows": 100,
        "evidence": False, "n_steps": 400, "max_steps": 400, "ess_target": 10.0, "rhat_target": 2.0,
        "output_dir": str(out), "calibration_windows": cal,
        **{f"calibration.{k}": v for k, v in {"n_chains": 8, "n_steps": 30, "max_steps": 30, "ess_target": 5.0,
                                               "rhat_target": 5.0, "seed": 4}.items()}})
    try:
        probe = subprocess.run([sys.executable, "-c", PROBE, str(structure), "5"], capture_output=True, text=True,
                               timeout=120)
        written = probe.returncode == 0 and _wait_file(out / "time" / "samples.npz", node, 240.0)
    finally:
        code, log = stop(node)
    assert probe.returncode == 0, probe.stderr[-3000:]
    assert written and code == 0, log[-3000:]
    modal = json.loads((out / "posterior.json").read_text())
    td = json.loads((out / "time" / "posterior.json").read_text())
    assert modal["diagnostics"]["likelihood"] != "time" and td["diagnostics"]["likelihood"] == "time"
    assert td["provenance"]["configuration"]["calibration_windows"] == cal
    assert td["provenance"]["random_seed"] == 4
    assert set(td["priors"]) == set(modal["parameters"])
    for name, s in modal["parameters"].items():  # the modal posterior is the time-domain step's prior
        prior = td["priors"][name]
        assert prior["dist"] == "normal", prior
        assert abs(prior["mean"] - s["mean"]) < 1e-12 and abs(prior["std"] - s["std"]) < 1e-12, (prior, s)
    # what the predict node reads to choose (with calibration windows: the time-domain one only)
    assert _likelihood(out / "posterior.json") != "time" and _likelihood(out / "time" / "posterior.json") == "time"


def test_bad_calibration_windows_stop_the_node_naming_the_parameter(tmp_path):
    """A missing or unreadable window file, or no output_dir to write to: the node stops at start
    with one line naming the parameter (not at its first time-domain step, minutes later)."""
    structure = str(ROOT / "examples" / "building.yaml")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a window file")
    cases = [({"output_dir": str(tmp_path / "u"), "calibration_windows": [str(tmp_path / "none.npz")]},
              "parameter 'calibration_windows'"),
             ({"output_dir": str(tmp_path / "u"), "calibration_windows": [str(bad)]},
              "parameter 'calibration_windows'"),
             ({"calibration_windows": [str(bad)]}, "'calibration_windows' needs 'output_dir'")]
    for params, said in cases:
        node = node_process("update", {"structure": structure, **params})
        try:
            log, _ = node.communicate(timeout=120.0)  # it stops by itself
        finally:
            stop(node)
        assert node.returncode == 2, log[-3000:]
        assert said in log and "Traceback" not in log, log[-3000:]
