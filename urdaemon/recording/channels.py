"""What a recording holds, declared once: each kind of message the cell publishes, its channel's topic,
schema and encoding, and how a published message becomes the recorded one and back.

``urdaemon record``, the daemon's flight recorder, ``urdaemon replay`` and ``urdaemon foxglove`` all
read this table. A message for which a standard ROS 2 type fits is stored as that type in CDR
(``joint_states`` → ``sensor_msgs/msg/JointState``, ``tcp_pose`` → ``geometry_msgs/msg/PoseStamped``,
``tf`` → ``tf2_msgs/msg/TFMessage``, the cell URDF → ``std_msgs/msg/String``); every other one as the
JSON the daemon published, with a JSON Schema (docs/recording.md lists them).

A topic is the Zenoh key with a leading ``/``, except a goal's messages: every goal of a robot shares
one topic (``/<cell>/<robot>/goal/feedback``, ``…/goal/result``; the message names its goal).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from urdaemon.recording import cdr, ros2_msgs
from urdaemon.recording.json_schemas import JSON_SCHEMAS
from urdaemon.recording.tf_tree import joint_transforms, world_poses

__all__ = [
    "CDR_KINDS",
    "DESCRIPTION_TOPIC",
    "KINDS",
    "RING_STREAMS",
    "ROBOT_DESCRIPTION",
    "Kind",
    "Schema",
    "Sorted",
    "kind_of",
    "record_bytes",
    "recorded_keys",
    "tf_record",
    "time_of",
]


@dataclass(frozen=True, slots=True)
class Schema:
    """A channel's schema as MCAP and Foxglove name it."""

    name: str
    encoding: str
    """``ros2msg`` or ``jsonschema``."""
    data: bytes


@dataclass(frozen=True, slots=True)
class Kind:
    """One kind of message: how it is recorded and how a recorded one is published again."""

    name: str
    """``joint_states``, ``status``, ``goal_result``, ...: the key's last chunk, or the goal's."""
    schema: Schema
    message_encoding: str
    """``cdr`` or ``json``."""
    to_record: Callable[[dict[str, Any], str], bytes]
    """The published message (decoded JSON) and its key → the recorded bytes."""
    to_message: Callable[[bytes, str], dict[str, Any]]
    """The recorded bytes and the topic → the message as the daemon publishes it (what CDR has no
    field for is left out, or ``None``: docs/recording.md says which)."""

    @property
    def is_ros2(self) -> bool:
        """Stored as a standard ROS 2 message (CDR), so ROS 2 tools read it."""
        return self.message_encoding == "cdr"


@dataclass(frozen=True, slots=True)
class Sorted:
    """Where a key goes: its kind, the channel's topic, and the key the message is published on again
    (a goal's key names its goal; the topic does not)."""

    kind: Kind
    topic: str
    cell: str
    robot: str | None


def time_of(message: dict[str, Any], fallback_ns: int) -> int:
    """The message's own ``host_time_ns`` (the time it describes), else ``fallback_ns``."""
    value = message.get("host_time_ns")
    if type(value) is int and value > 0:
        return value
    return fallback_ns


def _floats(values: Any) -> list[float]:
    """A JSON list of numbers, ``null`` (NaN never goes out) read back as NaN."""
    return [math.nan if v is None else float(v) for v in values]


def _joint_states_record(message: dict[str, Any], key: str) -> bytes:
    return cdr.encode_joint_state(
        time_of(message, 0),
        message["names"],
        _floats(message["position"]),
        _floats(message.get("velocity") or ()),
        _floats(message.get("effort") or ()),
    )


def _robot_of(topic: str) -> str:
    parts = topic.split("/")
    return parts[2] if len(parts) > 2 else ""


def _joint_states_message(data: bytes, topic: str) -> dict[str, Any]:
    m = cdr.decode_joint_state(data)
    return {
        "v": 1,
        "robot": _robot_of(topic),
        "names": list(m.names),
        "position": list(m.position),
        "velocity": list(m.velocity),
        "effort": list(m.effort),
        "controller_time": None,
        "host_time_ns": m.time_ns,
    }


def _tcp_pose_record(message: dict[str, Any], key: str) -> bytes:
    pose = [*_floats(message["position"]), *_floats(message["orientation"])]
    return cdr.encode_pose_stamped(time_of(message, 0), str(message.get("frame", "")), pose)


def _tcp_pose_message(data: bytes, topic: str) -> dict[str, Any]:
    m = cdr.decode_pose_stamped(data)
    return {
        "v": 1,
        "robot": _robot_of(topic),
        "frame": m.frame_id,
        "position": list(m.pose[:3]),
        "orientation": list(m.pose[3:]),
        "controller_time": None,
        "host_time_ns": m.time_ns,
    }


def _tf_record(message: dict[str, Any], key: str) -> bytes:
    links = message["links"]
    return cdr.encode_tf(
        time_of(message, 0), str(message.get("frame", "world")), [(n, _floats(v)) for n, v in links.items()]
    )


def tf_record(message: dict[str, Any], joints: Sequence[tuple[str, str]]) -> bytes:
    """The daemon's tf (every link's pose in ``world``) as the recorder and the Foxglove bridge store
    it next to the URDF: one transform per URDF joint, parent → child (``tf_tree.py``: a frame with two
    parents would fight the URDF in Foxglove's 3-D panel), in one ``tf2_msgs/msg/TFMessage``."""
    links = message["links"]
    if not isinstance(links, dict):
        raise ValueError("tf: links is not an object")
    root = str(message.get("frame", "world"))
    return cdr.encode_transforms(time_of(message, 0), joint_transforms(links, joints, root))


def record_bytes(
    kind: Kind, message: dict[str, Any], payload: bytes, key: str, joints: Sequence[tuple[str, str]]
) -> bytes:
    """What a published message (its JSON ``payload``, decoded as ``message``) is stored as: a JSON
    kind as it was published; tf, given the URDF's ``joints``, one transform per joint
    (``tf_record``); any other CDR kind its ``to_record``. The recorder and the Foxglove bridge both
    ask this."""
    if kind.message_encoding == "json":
        return payload
    if kind.name == "tf" and joints:
        return tf_record(message, joints)
    return kind.to_record(message, key)


def _tf_message(data: bytes, topic: str) -> dict[str, Any]:
    transforms = cdr.decode_tf(data)
    time_ns = transforms[0].time_ns if transforms else 0
    parents = {t.frame_id for t in transforms}
    children = {t.child_frame_id for t in transforms}
    roots = parents - children
    frame = roots.pop() if len(roots) == 1 else "world"
    tree = [(t.frame_id, t.child_frame_id, t.transform) for t in transforms]
    links = world_poses(tree, frame)
    return {"v": 1, "frame": frame, "links": {n: list(p) for n, p in links.items()}, "host_time_ns": time_ns}


def _json_record(message: dict[str, Any], key: str) -> bytes:
    return json.dumps(message, separators=(",", ":")).encode()


def _json_message(data: bytes, topic: str) -> dict[str, Any]:
    value = json.loads(data)
    if not isinstance(value, dict):
        raise ValueError(f"{topic}: a recorded message is not a JSON object")
    return value


def _ros2(name: str, message_type: str, to_record: Any, to_message: Any) -> Kind:
    schema = Schema(message_type, "ros2msg", ros2_msgs.schema_text(message_type).encode())
    return Kind(name, schema, "cdr", to_record, to_message)


def _json(name: str) -> Kind:
    title, schema = JSON_SCHEMAS[name]
    return Kind(
        name, Schema(title, "jsonschema", json.dumps(schema).encode()), "json", _json_record, _json_message
    )


KINDS: dict[str, Kind] = {
    "joint_states": _ros2("joint_states", ros2_msgs.JOINT_STATE, _joint_states_record, _joint_states_message),
    "tcp_pose": _ros2("tcp_pose", ros2_msgs.POSE_STAMPED, _tcp_pose_record, _tcp_pose_message),
    "tf": _ros2("tf", ros2_msgs.TF_MESSAGE, _tf_record, _tf_message),
    **{name: _json(name) for name in JSON_SCHEMAS},
}
"""Every kind recorded, by name."""

CDR_KINDS = frozenset(name for name, kind in KINDS.items() if kind.is_ros2)

ROBOT_DESCRIPTION = Schema(ros2_msgs.STRING, "ros2msg", ros2_msgs.schema_text(ros2_msgs.STRING).encode())
"""The cell URDF's channel's schema (one message at the start, as ``robot_state_publisher`` latches it),
besides the file's ``robot_description.urdf`` attachment."""

DESCRIPTION_TOPIC = "/robot_description"
"""The URDF's topic: the name ROS 2 gives it, and the one topic Foxglove's 3-D panel draws a URDF from
(a recording or a bridge serves one cell)."""

_ROBOT_KEYS = ("joint_states", "tcp_pose", "status", "io", "events", "servo_command")


RING_STREAMS = frozenset({"joint_states"})
"""The streams the daemon computes for the flight recorder's ring even while no client subscribes
(publish/tap.py). ``tcp_pose`` and ``tf`` are not: they follow from ``joint_states`` and the URDF,
and computing them for the ring would cost forward kinematics every cycle; they are in the ring only
while a client subscribes to them. What is published anyway (status, io, events, goal messages,
servo_command) always goes to the ring."""


def recorded_keys(cell: str) -> tuple[str, ...]:
    """The key expressions a recorder of ``cell`` subscribes to: everything the daemon publishes about
    what the cell did, and nothing that clients send."""
    return (
        *(f"{cell}/*/{name}" for name in _ROBOT_KEYS),
        f"{cell}/*/goal/*/feedback",
        f"{cell}/*/goal/*/result",
        f"{cell}/goal/*/result",
        f"{cell}/tf",
    )


def kind_of(key: str) -> Sorted | None:
    """Where a published key goes, or None for a key the recorder does not keep."""
    parts = key.split("/")
    if len(parts) < 2 or not all(parts):
        return None
    cell = parts[0]
    if len(parts) == 2 and parts[1] == "tf":
        return Sorted(KINDS["tf"], f"/{key}", cell, None)
    if len(parts) == 4 and parts[1] == "goal" and parts[3] == "result":
        return Sorted(KINDS["cell_goal_result"], f"/{cell}/goal/result", cell, None)
    if parts[1] in ("tf", "goal", "service", "robot_description"):
        return None
    robot = parts[1]
    if len(parts) == 3 and parts[2] in _ROBOT_KEYS:
        return Sorted(KINDS[parts[2]], f"/{key}", cell, robot)
    if len(parts) == 5 and parts[2] == "goal" and parts[4] in ("feedback", "result"):
        return Sorted(KINDS[f"goal_{parts[4]}"], f"/{cell}/{robot}/goal/{parts[4]}", cell, robot)
    return None
