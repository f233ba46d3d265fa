"""A sensor driver stand-in: publishes ``sensor_msgs/Imu`` with BEST_EFFORT QoS (what many IMU
drivers do), one message per sample, then says ``/shm/replay/done``.

    python best_effort_imu.py DATA.npz PREFIX RATE_MSG_PER_S

``DATA.npz`` holds ``stamps`` (n,) int64 ns, ``values`` (n, c) float64 and ``topics`` (c,) str;
channel j is published on ``PREFIX/accel/<topics[j]>`` with its value on x and gravity on z.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import rclpy
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu
from std_msgs.msg import String


def main() -> int:
    path, prefix, rate = sys.argv[1], sys.argv[2], float(sys.argv[3])
    d = np.load(path)
    stamps, values, names = d["stamps"], d["values"], [str(t) for t in d["topics"]]
    rclpy.init()
    node = rclpy.create_node("best_effort_imu")
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=50, reliability=ReliabilityPolicy.BEST_EFFORT,
                     durability=DurabilityPolicy.VOLATILE)
    pubs = [node.create_publisher(Imu, f"{prefix}/accel/{n}", qos) for n in names]
    done = node.create_publisher(String, "/shm/replay/done", QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    deadline = time.monotonic() + 20.0
    while any(p.get_subscription_count() == 0 for p in pubs) and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    if any(p.get_subscription_count() == 0 for p in pubs):
        print("no subscriber matched the best-effort topics", file=sys.stderr)
        return 1
    time.sleep(0.5)  # let the matched readers settle before data flows
    msg = Imu()
    msg.orientation_covariance[0] = -1.0
    msg.linear_acceleration.z = 9.80665
    t_start = time.monotonic()
    sent = 0
    for k in range(len(stamps)):
        sec, nsec = divmod(int(stamps[k]), 1_000_000_000)
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nsec
        for j, pub in enumerate(pubs):
            msg.linear_acceleration.x = float(values[k, j])
            pub.publish(msg)
            sent += 1
        while (ahead := sent / rate - (time.monotonic() - t_start)) > 0:
            time.sleep(min(ahead, 0.01))
    time.sleep(0.5)
    done.publish(String(data=f"best-effort {prefix}"))
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.1)
    print(f"published {sent} best-effort Imu messages")
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
