"""tf2_msgs built from its .msg file (msg_deps/tf2_msgs, ./dev setup) is the type the bags use: a
TFMessage serialised by rclpy reads back through the rosbags typestore field for field."""

from __future__ import annotations

from pathlib import Path

import pytest

MSG = Path(__file__).resolve().parents[1] / "msg_deps" / "tf2_msgs" / "msg" / "TFMessage.msg"


def test_the_definition_is_the_one_the_typestore_knows():
    from shm_ros.io.typestore import typestore

    fields = typestore().fielddefs["tf2_msgs/msg/TFMessage"][1]
    lines = [ln.split("#")[0].split() for ln in MSG.read_text().splitlines() if ln.split("#")[0].strip()]
    assert [(t, n) for t, n in lines] == [("geometry_msgs/TransformStamped[]", "transforms")]
    assert [f[0] for f in fields] == ["transforms"]


def test_rclpy_message_reads_back_through_rosbags():
    pytest.importorskip("rclpy")
    from geometry_msgs.msg import TransformStamped
    from rclpy.serialization import serialize_message
    from tf2_msgs.msg import TFMessage

    from shm_ros.io.typestore import typestore

    tr = TransformStamped()
    tr.header.frame_id, tr.child_frame_id = "odom", "rover/base_link"
    tr.header.stamp.sec, tr.header.stamp.nanosec = 12, 345
    tr.transform.translation.x, tr.transform.rotation.z, tr.transform.rotation.w = 3.5, 0.6, 0.8
    back = typestore().deserialize_cdr(serialize_message(TFMessage(transforms=[tr, tr])), "tf2_msgs/msg/TFMessage")
    assert len(back.transforms) == 2
    t = back.transforms[1]
    assert (t.header.frame_id, t.child_frame_id, t.header.stamp.sec, t.header.stamp.nanosec) == \
        ("odom", "rover/base_link", 12, 345)
    assert (t.transform.translation.x, t.transform.rotation.z, t.transform.rotation.w) == (3.5, 0.6, 0.8)
