"""Issue 2: two nodes in two processes exchange messages over real DDS on a clean set-up."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

HELPER = Path(__file__).resolve().parent / "ros_helpers" / "talker_listener.py"


def test_talker_and_listener_processes_exchange_every_message():
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert os.environ["ROS_DOMAIN_ID"]
    n = 500
    listener = subprocess.Popen([sys.executable, str(HELPER), "listen", str(n)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    talker = subprocess.Popen([sys.executable, str(HELPER), "talk", str(n)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out, err = listener.communicate(timeout=90)
    talker.communicate(timeout=90)
    assert listener.returncode == 0, err
    assert talker.returncode == 0
    stamps = [int(s) for s in out.split()]
    assert stamps == [1_700_000_000 + k for k in range(n)]


def test_other_domains_see_nothing():
    """Isolation: a listener on another domain receives nothing from this run's talker."""
    other = dict(os.environ, ROS_DOMAIN_ID=str((int(os.environ["ROS_DOMAIN_ID"]) + 37) % 200 + 1))
    code = (
        "import rclpy, time\n"
        "from sensor_msgs.msg import Imu\n"
        "rclpy.init(); n = rclpy.create_node('iso'); got = []\n"
        "n.create_subscription(Imu, '/smoke/accel/s1', got.append, 10)\n"
        "end = time.monotonic() + 4\n"
        "while time.monotonic() < end: rclpy.spin_once(n, timeout_sec=0.1)\n"
        "print(len(got))\n"
    )
    listener = subprocess.Popen([sys.executable, "-c", code], env=other, stdout=subprocess.PIPE, text=True)
    talker = subprocess.Popen([sys.executable, str(HELPER), "talk", "5"], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    out, _ = listener.communicate(timeout=60)
    talker.kill()
    talker.communicate()
    assert out.strip() == "0"
