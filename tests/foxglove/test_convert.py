"""A published sample → the Foxglove messages it becomes, read back with rosbags (an independent CDR
reader): joint states as the recorder writes them, tf as one message of parent → child transforms,
the URDF as a ``std_msgs/msg/String``; a key the recorder does not keep gives none, a bad payload a
clear error."""

from __future__ import annotations

import json
import math
from typing import Any

import pytest
from rosbags.typesys import Stores, get_typestore

from urdaemon.foxglove_bridge.convert import description_record, records_of
from urdaemon.recording.channels import KINDS

TYPES = get_typestore(Stores.ROS2_HUMBLE)
JOINTS = (("world", "a_base"), ("a_base", "a_l1"), ("a_base", "a_l2"))


def test_joint_states_as_the_recorder_writes_them() -> None:
    message = {
        "v": 1,
        "robot": "alice",
        "names": ["j1", "j2"],
        "position": [0.5, None],
        "velocity": [0.1, 0.2],
        "effort": [],
        "host_time_ns": 1_700_000_000_123_456_789,
    }
    payload = json.dumps(message).encode()
    [(topic, data, log_time)] = records_of("c/alice/joint_states", payload, 5, JOINTS)
    assert topic == "/c/alice/joint_states"
    assert log_time == message["host_time_ns"]
    assert data == KINDS["joint_states"].to_record(message, "c/alice/joint_states")
    read: Any = TYPES.deserialize_cdr(data, "sensor_msgs/msg/JointState")
    assert list(read.name) == ["j1", "j2"]
    assert read.position[0] == 0.5
    assert math.isnan(read.position[1])
    assert (read.header.stamp.sec, read.header.stamp.nanosec) == (1_700_000_000, 123_456_789)


def test_tf_goes_out_as_one_message_with_each_childs_pose_in_its_parent() -> None:
    message = {
        "v": 1,
        "frame": "world",
        "links": {
            "world": [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
            "a_base": [0.5, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0],  # turned half a turn about z
            "a_l1": [0.5, 0.0, 0.2, 0.0, 0.0, 1.0, 0.0],
            "a_l2": [0.4, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0],
        },
    }
    records = records_of("c/tf", json.dumps(message).encode(), 42, JOINTS)
    assert [(topic, log_time) for topic, _, log_time in records] == [("/c/tf", 42)]
    read: Any = TYPES.deserialize_cdr(records[0][1], "tf2_msgs/msg/TFMessage")
    assert [(t.header.frame_id, t.child_frame_id) for t in read.transforms] == [
        ("world", "a_base"),
        ("a_base", "a_l1"),
        ("a_base", "a_l2"),
    ]
    l2 = read.transforms[2].transform
    # 0.1 m towards -x in the world is +x in a_base, which is turned half a turn
    assert [l2.translation.x, l2.translation.y, l2.translation.z] == pytest.approx([0.1, 0.0, 0.0], abs=1e-12)
    assert abs(l2.rotation.w) == pytest.approx(1.0)


def test_the_urdf_is_a_string_message() -> None:
    topic, data, log_time = description_record("/robot_description", "<robot name='r'/>", 7)
    assert (topic, log_time) == ("/robot_description", 7)
    read: Any = TYPES.deserialize_cdr(data, "std_msgs/msg/String")
    assert read.data == "<robot name='r'/>"


def test_a_json_kind_is_the_daemons_message_and_its_time() -> None:
    message = {"v": 1, "robot": "alice", "kind": "estop", "host_time_ns": 99}
    [(topic, data, log_time)] = records_of("c/alice/events", json.dumps(message).encode(), 5, JOINTS)
    assert (topic, log_time) == ("/c/alice/events", 99)
    assert json.loads(data) == message


def test_a_key_the_recorder_does_not_keep_gives_nothing() -> None:
    assert records_of("c/alice/command/position", b"{}", 5, JOINTS) == []
    assert records_of("c/robot_description", b"<robot/>", 5, JOINTS) == []


@pytest.mark.parametrize(
    ("key", "payload", "error"),
    [
        ("c/alice/joint_states", b"[1, 2]", ValueError),
        ("c/alice/joint_states", b"not json", ValueError),
        ("c/alice/joint_states", b'{"v": 1}', KeyError),
        ("c/tf", b'{"links": [1]}', ValueError),
    ],
)
def test_a_payload_that_is_not_the_daemons_message_raises(key: str, payload: bytes, error: type) -> None:
    with pytest.raises(error):
        records_of(key, payload, 5, JOINTS)
