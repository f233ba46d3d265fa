"""The ingest node reports sensors and topics that do not fit together as soon as it can: a
publisher on a misspelled accelerometer topic gives a warning naming the topic and the structure
sensor it was probably meant for, and that sensor is reported unmatched once discovery settled
(real rclpy in its own process; the test waits for the diagnostics, not for a time)."""

from __future__ import annotations

import json
import subprocess
import sys

STRUCTURE = """
name: two-storey-test-frame
kind: shear_building
shear_building:
  floors:
    - {mass: 1.0e+5, stiffness: 2.0e+8}
    - {mass: 1.0e+5, stiffness: 2.0e+8}
sensors:
  - {id: deck_n1, at: {floor: 1}, direction: x}
  - {id: deck_s1, at: {floor: 2}, direction: x}
"""

SCRIPT = r"""
import json, sys, time
import rclpy
from rclpy.executors import SingleThreadedExecutor
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import Imu
from shm_ros.ros.ingest_node import IngestNode
from shm_ros.ros.qos import pipeline_qos, recording_qos

rclpy.init()
ingest = IngestNode("ingest", {"structure": sys.argv[1], "discovery_timeout_s": 2.0,
                               "discovery_period_s": 0.2})
probe = rclpy.create_node("probe")
imu_pub = probe.create_publisher(Imu, "/shm/accel/dekc_s1", recording_qos())  # misspelled
ok_pub = probe.create_publisher(Imu, "/shm/accel/deck_n1", recording_qos())
got = {}
def on_diag(msg):
    for s in msg.status:
        code = next((kv.value for kv in s.values if kv.key == "code"), "")
        if code in ("unknown_topic", "sensor_unmatched"):
            got.setdefault(code, {"level": s.level[0], "name": s.name, "message": s.message})
probe.create_subscription(DiagnosticArray, "/diagnostics", on_diag, pipeline_qos())
ex = SingleThreadedExecutor()
ex.add_node(ingest)
ex.add_node(probe)
end = time.monotonic() + 90
while len(got) < 2 and time.monotonic() < end:
    ex.spin_once(timeout_sec=0.1)
print(json.dumps(got))
ex.shutdown()
ingest.destroy_node()
probe.destroy_node()
rclpy.shutdown()
"""


def test_misspelled_topic_and_unmatched_sensor_are_reported_with_the_close_match(tmp_path):
    structure = tmp_path / "structure.yaml"
    structure.write_text(STRUCTURE)
    run = subprocess.run([sys.executable, "-c", SCRIPT, str(structure)], capture_output=True, text=True,
                         timeout=180)
    assert run.returncode == 0, run.stderr[-3000:]
    got = json.loads(run.stdout.strip().splitlines()[-1])
    assert set(got) == {"unknown_topic", "sensor_unmatched"}, (got, run.stderr[-3000:])
    topic, sensor = got["unknown_topic"], got["sensor_unmatched"]
    assert topic["level"] == 1 and sensor["level"] == 1  # WARN
    assert "/shm/accel/dekc_s1" in topic["name"] and "deck_s1" in topic["message"]
    assert "deck_s1" in sensor["name"] and "/shm/accel/dekc_s1" in sensor["message"]
    assert "deck_n1" not in sensor["name"]  # the sensor with a topic is not reported
    # and on the terminal, as warnings
    assert "dekc_s1" in run.stderr and "WARN" in run.stderr
