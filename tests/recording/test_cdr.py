"""The recorder's CDR encoders against rosbags' serializer, an implementation written by others.

Every encoder's bytes must equal what rosbags makes of the same message, and rosbags must read back
what we wrote; our decoders must read rosbags' bytes.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from rosbags.typesys import Stores, get_typestore

from urdaemon.recording import cdr

STORE = get_typestore(Stores.ROS2_HUMBLE)
Time = STORE.types["builtin_interfaces/msg/Time"]
Header = STORE.types["std_msgs/msg/Header"]
JointState = STORE.types["sensor_msgs/msg/JointState"]
PoseStamped = STORE.types["geometry_msgs/msg/PoseStamped"]
Pose = STORE.types["geometry_msgs/msg/Pose"]
Point = STORE.types["geometry_msgs/msg/Point"]
Quaternion = STORE.types["geometry_msgs/msg/Quaternion"]
TFMessage = STORE.types["tf2_msgs/msg/TFMessage"]
TransformStamped = STORE.types["geometry_msgs/msg/TransformStamped"]
Transform = STORE.types["geometry_msgs/msg/Transform"]
Vector3 = STORE.types["geometry_msgs/msg/Vector3"]
String = STORE.types["std_msgs/msg/String"]

times = st.integers(min_value=0, max_value=(2**31 - 1) * 1_000_000_000)
names = st.text(st.characters(exclude_categories=["Cs"], exclude_characters="\x00"), max_size=12)
floats = st.floats(allow_nan=False, width=64)


def _header(time_ns: int, frame: str) -> Any:
    sec, nanosec = divmod(time_ns, 1_000_000_000)
    return Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame)


def _serialized(message: Any, typename: str) -> bytes:
    return bytes(STORE.serialize_cdr(message, typename))


@given(times, st.lists(st.tuples(names, floats, floats, floats), max_size=9), names)
def test_joint_state_matches_rosbags(
    time_ns: int, joints: list[tuple[str, float, float, float]], frame: str
) -> None:
    joint_names = [j[0] for j in joints]
    position = [j[1] for j in joints]
    velocity = [j[2] for j in joints]
    effort = [j[3] for j in joints]
    ours = cdr.encode_joint_state(time_ns, joint_names, position, velocity, effort, frame)
    theirs = _serialized(
        JointState(
            header=_header(time_ns, frame),
            name=joint_names,
            position=np.array(position, dtype=np.float64),
            velocity=np.array(velocity, dtype=np.float64),
            effort=np.array(effort, dtype=np.float64),
        ),
        "sensor_msgs/msg/JointState",
    )
    assert ours == theirs
    back = cdr.decode_joint_state(theirs)
    assert (back.time_ns, back.frame_id, back.names) == (time_ns, frame, tuple(joint_names))
    assert (back.position, back.velocity, back.effort) == (tuple(position), tuple(velocity), tuple(effort))


def test_joint_state_with_empty_velocity_and_effort() -> None:
    ours = cdr.encode_joint_state(5, ["a", "bc"], [1.0, 2.0], [], [])
    read: Any = STORE.deserialize_cdr(ours, "sensor_msgs/msg/JointState")
    assert read.name == ["a", "bc"]
    assert list(read.position) == [1.0, 2.0]
    assert len(read.velocity) == 0
    assert len(read.effort) == 0


@given(times, names, st.lists(floats, min_size=7, max_size=7))
def test_pose_stamped_matches_rosbags(time_ns: int, frame: str, pose: list[float]) -> None:
    ours = cdr.encode_pose_stamped(time_ns, frame, pose)
    theirs = _serialized(
        PoseStamped(
            header=_header(time_ns, frame),
            pose=Pose(
                position=Point(x=pose[0], y=pose[1], z=pose[2]),
                orientation=Quaternion(x=pose[3], y=pose[4], z=pose[5], w=pose[6]),
            ),
        ),
        "geometry_msgs/msg/PoseStamped",
    )
    assert ours == theirs
    back = cdr.decode_pose_stamped(theirs)
    assert (back.time_ns, back.frame_id, back.pose) == (time_ns, frame, tuple(pose))


@given(times, names, st.lists(st.tuples(names, st.lists(floats, min_size=7, max_size=7)), max_size=6))
def test_tf_matches_rosbags(time_ns: int, frame: str, links: list[tuple[str, list[float]]]) -> None:
    ours = cdr.encode_tf(time_ns, frame, links)
    theirs = _serialized(
        TFMessage(
            transforms=[
                TransformStamped(
                    header=_header(time_ns, frame),
                    child_frame_id=child,
                    transform=Transform(
                        translation=Vector3(x=t[0], y=t[1], z=t[2]),
                        rotation=Quaternion(x=t[3], y=t[4], z=t[5], w=t[6]),
                    ),
                )
                for child, t in links
            ]
        ),
        "tf2_msgs/msg/TFMessage",
    )
    assert ours == theirs
    back = cdr.decode_tf(theirs)
    assert [(t.child_frame_id, list(t.transform)) for t in back] == [(c, t) for c, t in links]
    assert all((t.time_ns, t.frame_id) == (time_ns, frame) for t in back)


@given(st.text(st.characters(exclude_categories=["Cs"], exclude_characters="\x00"), max_size=300))
def test_string_matches_rosbags(text: str) -> None:
    ours = cdr.encode_string(text)
    assert ours == _serialized(String(data=text), "std_msgs/msg/String")
    assert cdr.decode_string(ours) == text


def test_a_time_past_int32_seconds_is_refused() -> None:
    with pytest.raises(ValueError, match="int32 seconds"):
        cdr.encode_pose_stamped(2**31 * 1_000_000_000, "", [0.0] * 7)


def test_nan_survives_the_round_trip() -> None:
    back = cdr.decode_joint_state(cdr.encode_joint_state(1, ["a"], [math.nan], [], []))
    assert math.isnan(back.position[0])


@pytest.mark.parametrize(
    ("data", "problem"),
    [
        (b"", "not little-endian CDR"),
        (b"\x00\x00\x00\x00" + bytes(8), "not little-endian CDR"),
        (cdr.encode_joint_state(1, ["alice_shoulder"], [1.0], [], [])[:-9], "before byte"),
        (cdr.HEADER + bytes(8) + b"\x05\x00\x00\x00abcde", "closing NUL"),
        (
            cdr.HEADER + bytes(8) + b"\x01\x00\x00\x00\x00" + b"\x00\x00\x00" + b"\xff\xff\xff\x7f",
            "cannot fit",
        ),
    ],
)
def test_malformed_bytes_are_refused_naming_why(data: bytes, problem: str) -> None:
    with pytest.raises(ValueError, match=problem):
        cdr.decode_joint_state(data)


def test_transforms_each_with_its_own_parent_match_rosbags() -> None:
    pose = [0.1, 0.2, 0.3, 0.0, 0.0, 0.0, 1.0]
    ours = cdr.encode_transforms(7, [("world", "a", pose), ("a", "b", pose)])
    read: Any = STORE.deserialize_cdr(ours, "tf2_msgs/msg/TFMessage")
    assert [(t.header.frame_id, t.child_frame_id) for t in read.transforms] == [("world", "a"), ("a", "b")]
    assert [(t.frame_id, t.child_frame_id) for t in cdr.decode_tf(ours)] == [("world", "a"), ("a", "b")]
