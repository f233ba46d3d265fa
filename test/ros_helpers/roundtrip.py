"""Two-process round trip of the project's interfaces over DDS.

``python roundtrip.py send SEED`` publishes one random message of every type (deterministic for the
seed; a 6 MB Window among them) once a subscriber is matched, and waits for the receiver to be done.
``python roundtrip.py receive OUTDIR`` stores the CDR bytes of each received message as
``OUTDIR/<Type>.cdr`` and exits when every type has arrived.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

TYPES = ["AccelBlock", "Window", "Mode", "ModalEstimate", "TrackedModes", "ParameterEstimate",
         "PosteriorSummary", "ResponsePrediction", "MissingPhysics", "Verdict"]
BIG_WINDOW_SAMPLES = 60_000 * 12  # a 10-minute, 12-channel window at 100 Hz: 5.8 MB of samples


def rclpy_class(type_name: str) -> type:
    from rosmsg_utils import rclpy_class as _cls

    return _cls(type_name)


def expected_messages(seed: int) -> dict[str, object]:
    import shm_interfaces.msg as m
    from rosmsg_utils import random_message

    rng = np.random.default_rng(seed)
    out = {name: random_message(getattr(m, name), rng) for name in TYPES}
    big = out["Window"]
    big.samples = rng.standard_normal(BIG_WINDOW_SAMPLES)
    big.flags = rng.integers(0, 64, BIG_WINDOW_SAMPLES, dtype=np.int64).astype(np.uint8)
    big.channel_names = [f"c{i}" for i in range(12)]
    big.n_samples = 60_000
    return out


def qos():
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def send(seed: int, timeout: float = 60.0) -> int:
    import rclpy
    import shm_interfaces.msg as m
    from std_msgs.msg import Empty

    rclpy.init()
    node = rclpy.create_node("roundtrip_sender")
    done = {"flag": False}
    node.create_subscription(Empty, "/roundtrip/done", lambda _: done.update(flag=True), qos())
    pubs = {name: node.create_publisher(getattr(m, name), f"/roundtrip/{name}", qos()) for name in TYPES}
    msgs = expected_messages(seed)
    deadline = time.monotonic() + timeout
    while any(p.get_subscription_count() == 0 for p in pubs.values()):
        rclpy.spin_once(node, timeout_sec=0.05)
        if time.monotonic() > deadline:
            print("no receiver matched", file=sys.stderr)
            return 1
    for name in TYPES:
        pubs[name].publish(msgs[name])
    while not done["flag"] and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    node.destroy_node()
    rclpy.shutdown()
    return 0 if done["flag"] else 2


def receive(outdir: Path, timeout: float = 60.0) -> int:
    import rclpy
    import shm_interfaces.msg as m
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Empty

    rclpy.init()
    node = rclpy.create_node("roundtrip_receiver")
    got: dict[str, bytes] = {}

    def keep(name):
        return lambda msg: got.setdefault(name, serialize_message(msg))

    subs = [node.create_subscription(getattr(m, name), f"/roundtrip/{name}", keep(name), qos())
            for name in TYPES]
    done_pub = node.create_publisher(Empty, "/roundtrip/done", qos())
    deadline = time.monotonic() + timeout
    while len(got) < len(TYPES) and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    outdir.mkdir(parents=True, exist_ok=True)
    for name, data in got.items():
        (outdir / f"{name}.cdr").write_bytes(data)
    done_pub.publish(Empty())
    end = time.monotonic() + 2.0
    while time.monotonic() < end and done_pub.get_subscription_count() > 0:
        rclpy.spin_once(node, timeout_sec=0.1)
    del subs
    node.destroy_node()
    rclpy.shutdown()
    return 0 if len(got) == len(TYPES) else 3


if __name__ == "__main__":
    if sys.argv[1] == "send":
        sys.exit(send(int(sys.argv[2])))
    sys.exit(receive(Path(sys.argv[2])))
