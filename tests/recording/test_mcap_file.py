"""The recording file: written with our writer, read back with the mcap library's reader and with
rosbags (as a rosbag2 bag); every message checked against what was published."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from urdaemon.recording import cdr
from urdaemon.recording.channels import kind_of, recorded_keys
from urdaemon.recording.mcap_file import URDF_ATTACHMENT, RecordingWriter, key_of, read_recording
from urdaemon.recording.rosbag2 import write_bag_metadata

T0 = 1_764_000_000_000_000_000
URDF = '<robot name="demo_cell"><link name="world"/></robot>'
NAMES = [f"alice_j{i}" for i in range(6)]


def _joint_states(i: int) -> dict[str, Any]:
    return {
        "v": 1,
        "robot": "alice",
        "names": NAMES,
        "position": [0.1 * i + j for j in range(6)],
        "velocity": [0.01 * j for j in range(6)],
        "effort": [0.0] * 6,
        "controller_time": 12.0 + 0.002 * i,
        "host_time_ns": T0 + 2_000_000 * i,
        "cycle": i,
    }


def _published() -> list[tuple[str, dict[str, Any]]]:
    out: list[tuple[str, dict[str, Any]]] = []
    for i in range(5):
        out.append(("demo_cell/alice/joint_states", _joint_states(i)))
        out.append(
            (
                "demo_cell/alice/tcp_pose",
                {
                    "robot": "alice",
                    "frame": "alice_base",
                    "child": "alice_tool0",
                    "position": [0.1, 0.2, 0.3 + i],
                    "orientation": [0.0, 0.0, 0.0, 1.0],
                    "host_time_ns": T0 + 2_000_000 * i + 1,
                },
            )
        )
    out.append(
        (
            "demo_cell/tf",
            {"frame": "world", "links": {"alice_base_link": [0, 0, 0, 0, 0, 0, 1]}, "host_time_ns": T0 + 5},
        )
    )
    out.append(("demo_cell/alice/status", {"robot": "alice", "lifecycle": "running", "host_time_ns": T0 + 7}))
    out.append(
        (
            "demo_cell/alice/goal/g1/feedback",
            {"robot": "alice", "goal_id": "g1", "progress": 0.5, "host_time_ns": T0 + 8},
        )
    )
    out.append(
        (
            "demo_cell/alice/goal/g1/result",
            {"robot": "alice", "goal_id": "g1", "status": "succeeded", "host_time_ns": T0 + 9},
        )
    )
    out.append(
        (
            "demo_cell/goal/c1/result",
            {"goal_id": "c1", "status": "succeeded", "robots": {}, "host_time_ns": T0 + 10},
        )
    )
    return out


def _write(ros2_only: bool = False) -> bytes:
    buffer = io.BytesIO()
    writer = RecordingWriter(buffer, cell="demo_cell", urdf=URDF, ros2_only=ros2_only)
    for key, message in _published():
        writer.add(key, json.dumps(message).encode(), receive_ns=1)
    writer.finish()
    return buffer.getvalue()


def test_every_message_reads_back_as_published() -> None:
    data = _write()
    read = list(read_recording(io.BytesIO(data)))
    urdf = [r for r in read if r.kind is None]
    assert [r.message["urdf"] for r in urdf] == [URDF]
    rest = [r for r in read if r.kind is not None]
    published = sorted(_published(), key=lambda p: p[1]["host_time_ns"])
    assert [key_of(r.topic, r.message) for r in rest] == [key for key, _ in published]
    assert [r.log_time_ns for r in rest] == [m["host_time_ns"] for _, m in published]
    for record, (_key, message) in zip(rest, published, strict=True):
        for field in ("names", "position", "velocity", "effort", "orientation", "links", "goal_id", "status"):
            if field in message:
                assert record.message[field] == message[field], field


def test_the_mcap_reader_sees_schemas_times_and_the_urdf_attachment() -> None:
    reader = make_reader(io.BytesIO(_write()))
    summary = reader.get_summary()
    assert summary is not None
    encodings = {
        c.topic: (c.message_encoding, summary.schemas[c.schema_id].name) for c in summary.channels.values()
    }
    assert encodings["/demo_cell/alice/joint_states"] == ("cdr", "sensor_msgs/msg/JointState")
    assert encodings["/demo_cell/alice/tcp_pose"] == ("cdr", "geometry_msgs/msg/PoseStamped")
    assert encodings["/demo_cell/tf"] == ("cdr", "tf2_msgs/msg/TFMessage")
    assert encodings["/demo_cell/alice/status"] == ("json", "urdaemon/Status")
    assert encodings["/robot_description"] == ("cdr", "std_msgs/msg/String")
    for _schema, _channel, message in reader.iter_messages():
        assert message.publish_time == message.log_time
    attachments = list(make_reader(io.BytesIO(_write())).iter_attachments())
    assert [(a.name, a.data.decode()) for a in attachments] == [(URDF_ATTACHMENT, URDF)]


def test_a_ros2_only_file_is_a_bag_rosbags_reads(tmp_path: Path) -> None:
    bag = tmp_path / "run"
    bag.mkdir()
    (bag / "run_0.mcap").write_bytes(_write(ros2_only=True))
    write_bag_metadata(bag / "run_0.mcap")
    with AnyReader([bag]) as reader:
        seen: dict[str, list[Any]] = {}
        for connection, timestamp, raw in reader.messages():
            seen.setdefault(connection.topic, []).append(
                (timestamp, reader.deserialize(raw, connection.msgtype))
            )
    assert set(seen) == {
        "/demo_cell/alice/joint_states",
        "/demo_cell/alice/tcp_pose",
        "/demo_cell/tf",
        "/robot_description",
    }
    states = seen["/demo_cell/alice/joint_states"]
    assert [t for t, _ in states] == [T0 + 2_000_000 * i for i in range(5)]
    for i, (_t, msg) in enumerate(states):
        assert msg.name == NAMES
        assert list(msg.position) == _joint_states(i)["position"]
        assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == T0 + 2_000_000 * i
    pose = seen["/demo_cell/alice/tcp_pose"][4][1]
    assert (pose.header.frame_id, pose.pose.position.z) == ("alice_base", 4.3)
    tf = seen["/demo_cell/tf"][0][1]
    assert [t.child_frame_id for t in tf.transforms] == ["alice_base_link"]
    assert seen["/robot_description"][0][1].data == URDF


def test_a_bag_of_json_channels_is_refused_naming_the_channel(tmp_path: Path) -> None:
    (tmp_path / "x.mcap").write_bytes(_write())
    with pytest.raises(ValueError, match="/demo_cell/alice/status is not a ROS 2"):
        write_bag_metadata(tmp_path / "x.mcap")


def test_unknown_keys_and_malformed_messages_are_counted_not_written() -> None:
    writer = RecordingWriter(io.BytesIO(), cell="demo_cell")
    assert not writer.add("demo_cell/alice/command/joint_position", b"{}", 1)
    assert not writer.add("demo_cell/alice/joint_states", b"[1]", 1)
    assert not writer.add("demo_cell/alice/joint_states", b'{"names": ["a"]}', 1)
    assert writer.counts.skipped == 1
    assert set(writer.counts.malformed) == {"demo_cell/alice/joint_states"}
    assert writer.counts.written == {}


@pytest.mark.parametrize(
    ("key", "topic"),
    [
        ("c/alice/joint_states", "/c/alice/joint_states"),
        ("c/alice/goal/abc/feedback", "/c/alice/goal/feedback"),
        ("c/alice/goal/abc/result", "/c/alice/goal/result"),
        ("c/goal/abc/result", "/c/goal/result"),
        ("c/tf", "/c/tf"),
        ("c/alice/command/twist", None),
        ("c/alice/service/stop", None),
        ("c/alice/lease", None),
        ("c/robot_description", None),
        ("c//joint_states", None),
    ],
)
def test_keys_sort_into_topics(key: str, topic: str | None) -> None:
    found = kind_of(key)
    assert (None if found is None else found.topic) == topic


def test_every_recorded_key_expression_sorts_a_concrete_key() -> None:
    for expression in recorded_keys("c"):
        concrete = expression.replace("*", "x")
        assert kind_of(concrete) is not None, expression


CHAIN = """<robot name="c">
  <link name="world"/><link name="a_base"/><link name="a_l1"/>
  <joint name="a_mount" type="fixed"><parent link="world"/><child link="a_base"/></joint>
  <joint name="a_j1" type="revolute"><parent link="a_base"/><child link="a_l1"/></joint>
</robot>"""


def test_tf_is_written_per_urdf_joint_and_read_back_as_world_poses() -> None:
    links = {"a_base": [0.5, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0], "a_l1": [0.5, 0.0, 0.2, 0.0, 0.0, 1.0, 0.0]}
    buffer = io.BytesIO()
    writer = RecordingWriter(buffer, cell="c", urdf=CHAIN)
    message = {"frame": "world", "links": links, "host_time_ns": T0}
    assert writer.add("c/tf", json.dumps(message).encode(), 1)
    writer.finish()
    reader = make_reader(io.BytesIO(buffer.getvalue()))
    raw = [m.data for _s, c, m in reader.iter_messages() if c.topic == "/c/tf"]
    transforms = cdr.decode_tf(raw[0])
    assert [(t.frame_id, t.child_frame_id) for t in transforms] == [("world", "a_base"), ("a_base", "a_l1")]
    assert transforms[1].transform == pytest.approx((0.0, 0.0, 0.2, 0.0, 0.0, 0.0, 1.0), abs=1e-12)
    (read,) = [r for r in read_recording(io.BytesIO(buffer.getvalue())) if r.topic == "/c/tf"]
    assert read.message["frame"] == "world"
    for name, pose in links.items():
        assert read.message["links"][name] == pytest.approx(pose, abs=1e-12)
