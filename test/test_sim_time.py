"""`shm-ros replay --clock` publishes /clock with the recording's time, as `ros2 bag play --clock`
does: nodes started with use_sim_time:=true then live in recording time (their clocks, hence the
stamps of their diagnostics and the recorder's log times), not in wall time."""

from __future__ import annotations

import numpy as np
from ros_helpers.graph import node_process, replay, running, wait_for_windows

FS = 50.0
T0 = 1_714_521_600_000_000_000  # 2024-05-01T00:00:00Z: years before any wall time of a test run
SPAN_S = 40.0
STRUCTURE = """
name: two-storey
kind: shear_building
shear_building:
  floors: [{mass: 1.0e+5, stiffness: 2.0e+8}, {mass: 1.0e+5, stiffness: 2.0e+8}]
sensors:
  - {id: f1, at: {floor: 1}, direction: x}
  - {id: f2, at: {floor: 2}, direction: x}
"""


def test_nodes_on_sim_time_see_the_recordings_time(tmp_path):
    from shm_ros.io.bags import BagWriter, read_messages

    (tmp_path / "s.yaml").write_text(STRUCTURE)
    n = int(SPAN_S * FS)
    stamps = T0 + np.round(np.arange(n) * 1e9 / FS).astype(np.int64)
    rng = np.random.default_rng(3)
    with BagWriter(tmp_path / "bag") as w:
        w.imu_streams({f"/site/accel/{s}": (stamps, rng.standard_normal((n, 3)) * 0.01) for s in ("f1", "f2")})
    out = tmp_path / "out"
    sim = {"use_sim_time": True}
    ingest = node_process("ingest", {"structure": str(tmp_path / "s.yaml"), "window_s": 10.0, **sim})
    recorder = node_process("recorder", {"output": str(out), "topics": ["/shm/windows", "/diagnostics"], **sim})
    with running(ingest, recorder, subscribers={"/shm/windows": 1}, publishers={"/shm/ingest/received": 1}):
        rep = replay(tmp_path / "bag", "--clock", "--clock-readers", "2")
        # the replay ends when ingest has acknowledged the samples; the last window may still be on
        # its way to the recorder: stop the nodes once it is in the open split (or after 60 s)
        wait_for_windows(out, 4)
    assert rep.returncode == 0, rep.stdout + rep.stderr

    end = T0 + int(SPAN_S * 1e9)
    windows = [m for m in read_messages(out) if m.topic == "/shm/windows"]
    diags = [m for m in read_messages(out) if m.topic == "/diagnostics"]
    assert len(windows) == 4 and diags
    # the recorder's clock: messages are logged at recording times (not at wall time, 2 years on).
    # Until a node has taken its first /clock message its ROS time is 0 (ROS's rule; on a busy
    # machine a window can reach the recorder before the clock does): 0 or inside the recording.
    logged = [m.receive_ns for m in windows + diags]
    assert all(t == 0 or T0 <= t <= end + 10**9 for t in logged), logged
    assert sum(T0 <= m.receive_ns <= end + 10**9 for m in windows) >= len(windows) // 2
    # the nodes' clocks: their diagnostics are stamped in recording time (or 0 before /clock)
    stamps = [int(m.decode().header.stamp.sec) * 10**9 + int(m.decode().header.stamp.nanosec) for m in diags]
    in_time = [t for t in stamps if t != 0]
    assert in_time and all(T0 <= t <= end + 10**9 for t in in_time), stamps
    # the windows carry the recording's sample times
    starts = sorted(int(w.decode().header.stamp.sec) * 10**9 + int(w.decode().header.stamp.nanosec) for w in windows)
    assert starts == [T0 + k * 10**10 for k in range(4)]
