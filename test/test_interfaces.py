"""Every custom interface round-trips through rclpy across two processes and through
rosbags (write, read back, identical values), including a 6 MB Window."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rosmsg_utils import to_plain
from ros_helpers.roundtrip import TYPES, expected_messages

HELPER = Path(__file__).resolve().parent / "ros_helpers" / "roundtrip.py"
SEED = 20241


def _rosbags_type(name: str) -> str:
    return f"shm_interfaces/msg/{name}"


def test_every_interface_is_in_the_typestore():
    from shm_ros.io.typestore import message_definitions, typestore

    ts = typestore()
    defined = {k.split("/")[-1] for k in message_definitions()}
    assert defined == set(TYPES)
    for name in TYPES:
        assert _rosbags_type(name) in ts.types


def test_interfaces_round_trip_between_two_processes(tmp_path):
    from rclpy.serialization import deserialize_message

    from shm_ros.io.typestore import typestore

    env = dict(os.environ)
    receiver = subprocess.Popen([sys.executable, str(HELPER), "receive", str(tmp_path)], env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    sender = subprocess.Popen([sys.executable, str(HELPER), "send", str(SEED)], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out_r, _ = receiver.communicate(timeout=120)
    out_s, _ = sender.communicate(timeout=120)
    assert receiver.returncode == 0, out_r
    assert sender.returncode == 0, out_s

    expected = expected_messages(SEED)
    ts = typestore()
    for name in TYPES:
        received = (tmp_path / f"{name}.cdr").read_bytes()
        # The same values when decoded by rclpy (CDR padding bytes are unspecified, so compare
        # values, not bytes)...
        from ros_helpers.roundtrip import rclpy_class

        back = deserialize_message(received, rclpy_class(f"shm_interfaces/{name}"))
        assert to_plain(back) == to_plain(expected[name]), name
        # ...and when decoded without ROS, by rosbags.
        decoded = ts.deserialize_cdr(received, _rosbags_type(name))
        assert to_plain(decoded) == to_plain(expected[name]), name
    big = (tmp_path / "Window.cdr").stat().st_size
    assert big > 6_000_000  # the 10-minute, 12-channel window really crossed DDS


@pytest.mark.parametrize("storage,compress", [("mcap", False), ("mcap", True), ("sqlite3", False)])
def test_interfaces_round_trip_through_rosbags(tmp_path, storage, compress):
    from rclpy.serialization import serialize_message

    from shm_ros.io.bags import BagWriter, read_messages
    from shm_ros.io.typestore import typestore

    ts = typestore()
    expected = expected_messages(SEED + 1)
    bag = tmp_path / "bag"
    with BagWriter(bag, storage=storage, compress=compress) as writer:
        for k, name in enumerate(TYPES):
            # Written from the rosbags object decoded from rclpy's CDR: both sides of the bridge.
            obj = ts.deserialize_cdr(serialize_message(expected[name]), _rosbags_type(name))
            writer.write(f"/rt/{name}", _rosbags_type(name), 1_700_000_000_000_000_000 + k, obj)
    got = {m.topic.split("/")[-1]: m for m in read_messages(bag)}
    assert set(got) == set(TYPES)
    for name in TYPES:
        assert got[name].msgtype == _rosbags_type(name)
        assert to_plain(got[name].decode()) == to_plain(expected[name]), name
    samples = np.asarray(got["Window"].decode().samples)
    assert samples.size == 60_000 * 12
    assert np.array_equal(samples, np.asarray(expected["Window"].samples))


def test_bag_metadata_carries_type_hashes(tmp_path):
    import yaml

    from shm_ros.io.bags import ACCEL_BLOCK, BagWriter

    with BagWriter(tmp_path / "b") as writer:
        writer.accel_block("/daq/accel_block", 10**18, 100.0, ["a"], np.zeros((3, 1)))
    meta = yaml.safe_load((tmp_path / "b" / "metadata.yaml").read_text())
    topics = meta["rosbag2_bagfile_information"]["topics_with_message_count"]
    hashes = [t["topic_metadata"].get("type_description_hash", "") for t in topics]
    # The hash rosidl computed when it built the interface package, as `ros2 bag` expects it.
    import json

    from shm_ros.io.typestore import msg_dir

    built = json.loads((msg_dir() / "AccelBlock.json").read_text())
    assert built["type_hashes"][0]["hash_string"] in hashes
    assert topics[0]["topic_metadata"]["type"] == ACCEL_BLOCK
