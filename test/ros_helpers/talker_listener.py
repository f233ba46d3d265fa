"""A minimal talker/listener pair for the DDS smoke test (one process each).

``talk N`` publishes N sensor_msgs/Imu with increasing stamps once a listener is matched;
``listen N`` prints the stamps it received, in order, then exits.
``stream`` prints ``ready`` once its publisher exists, then publishes one message every 20 ms
(stamps increasing) until its stdin is closed.
``watch N`` prints ``ready`` once subscribed, then the number of messages it received when it has
N of them or when its stdin is closed (whichever comes first), then exits.
"""

from __future__ import annotations

import sys
import threading
import time


def _stdin_closed() -> threading.Event:
    """An event set when this process's stdin is closed (the test's way to say stop)."""
    closed = threading.Event()

    def wait_for_eof() -> None:
        sys.stdin.read()
        closed.set()

    threading.Thread(target=wait_for_eof, daemon=True).start()
    return closed


def main(role: str, n: int) -> int:
    import rclpy
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Imu

    qos = QoSProfile(depth=n, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
    rclpy.init()
    node = rclpy.create_node(f"smoke_{role}")
    deadline = time.monotonic() + 60
    if role == "talk":
        pub = node.create_publisher(Imu, "/smoke/accel/s1", qos)
        while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        for k in range(n):
            msg = Imu()
            msg.header.stamp.sec = 1_700_000_000 + k
            msg.linear_acceleration.z = 9.80665 + k * 1e-3
            pub.publish(msg)
        # stay until the listener is gone (it leaves after receiving everything)
        while pub.get_subscription_count() > 0 and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.05)
        ok = time.monotonic() < deadline
    elif role == "stream":
        pub = node.create_publisher(Imu, "/smoke/accel/s1", qos)
        closed = _stdin_closed()
        print("ready", flush=True)
        k = 0
        while not closed.wait(0.02) and time.monotonic() < deadline:
            msg = Imu()
            msg.header.stamp.sec = 1_700_000_000 + k
            pub.publish(msg)
            k += 1
        ok = time.monotonic() < deadline
    elif role == "watch":
        count = [0]
        node.create_subscription(Imu, "/smoke/accel/s1", lambda m: count.__setitem__(0, count[0] + 1), qos)
        closed = _stdin_closed()
        print("ready", flush=True)
        while count[0] < n and not closed.is_set() and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.05)
        print(count[0], flush=True)
        ok = time.monotonic() < deadline
    else:
        got: list[int] = []
        node.create_subscription(Imu, "/smoke/accel/s1", lambda m: got.append(m.header.stamp.sec), qos)
        while len(got) < n and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
        print(" ".join(str(s) for s in got))
        ok = len(got) == n
    node.destroy_node()
    rclpy.shutdown()
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 1))
