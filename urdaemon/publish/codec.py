"""The one message encoding: UTF-8 JSON objects carrying ``"v": 1`` (docs/keys.md).

Decoders take what a client sent and return typed values or raise ``MessageError`` naming the
field and the problem. Range checks against a robot (limits, joint names, NaN) belong to the
controller, which rejects with its own reasons; here only the shape and types are checked.
"""

from __future__ import annotations

import contextlib
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from urdaemon.control.goals import GoalFeedback, GoalResult, TrajectoryPoint
from urdaemon.errors import MessageError
from urdaemon.model import RobotState

__all__ = [
    "SCHEMA_VERSION",
    "JointStateEncoder",
    "MoveGoalMessage",
    "StreamMessage",
    "ToleranceMessage",
    "TrajectoryGoalMessage",
    "decode_cancel",
    "decode_dashboard",
    "decode_force_mode",
    "decode_freedrive",
    "decode_message",
    "decode_move_goal",
    "decode_set_io",
    "decode_set_payload",
    "decode_speed_slider",
    "decode_stream_position",
    "decode_stream_velocity",
    "decode_tool_voltage",
    "decode_trajectory_goal",
    "encode",
    "encode_feedback",
    "encode_result",
]

SCHEMA_VERSION = 1
MAX_MESSAGE_BYTES = 2 * 1024 * 1024
"""Largest client message accepted (5 000 points with positions, velocities and accelerations: ~1.9 MB)."""
MAX_TRAJECTORY_POINTS = 5_000
"""Planning is sliced between cycles, but decoding and checking a goal (~25 µs a point) is not yet:
5 000 points keep that one-off stall near 0.1 s (docs/keys.md)."""


@dataclass(frozen=True, slots=True)
class ToleranceMessage:
    """Tolerances as sent: a number for every joint, or one per joint in the goal's joint order."""

    path: float | tuple[float, ...] | None = None
    goal: float | tuple[float, ...] | None = None
    goal_time: float | None = None


@dataclass(frozen=True, slots=True)
class TrajectoryGoalMessage:
    """A decoded trajectory goal."""

    joint_names: tuple[str, ...] | None
    points: tuple[TrajectoryPoint, ...]
    tolerances: ToleranceMessage
    preempt: bool
    passthrough: bool = False
    """Forward the points to the robot, which interpolates them itself (UR controllers only)."""


@dataclass(frozen=True, slots=True)
class MoveGoalMessage:
    """A decoded point-to-point move goal."""

    joint_names: tuple[str, ...] | None
    positions: tuple[float, ...]
    duration: float | None
    velocity_scale: float
    acceleration_scale: float
    tolerances: ToleranceMessage
    preempt: bool


@dataclass(frozen=True, slots=True)
class StreamMessage:
    """A decoded streaming command."""

    joint_names: tuple[str, ...] | None
    positions: tuple[float, ...] | None
    velocities: tuple[float, ...] | None


def encode(message: dict[str, Any]) -> bytes:
    """Encode a message dict, adding the schema version; NaN and infinities become null."""
    body = {"v": SCHEMA_VERSION, **message}
    try:
        return json.dumps(body, separators=(",", ":"), allow_nan=False).encode()
    except ValueError:  # a non-finite float somewhere: JSON has no such numbers
        return json.dumps(_finite_or_null(body), separators=(",", ":"), allow_nan=False).encode()


def _finite_or_null(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite_or_null(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite_or_null(v) for v in value]
    return value


def decode_message(payload: bytes | bytearray | memoryview | None, what: str) -> dict[str, Any]:
    """Parse a client message into a dict, checking size, JSON syntax, object shape and version."""
    if payload is None or len(payload) == 0:
        raise MessageError(f"{what}: empty message; expected a JSON object")
    if len(payload) > MAX_MESSAGE_BYTES:
        raise MessageError(f"{what}: message of {len(payload)} bytes exceeds {MAX_MESSAGE_BYTES}")
    try:
        data = json.loads(bytes(payload))
    except (ValueError, RecursionError) as err:  # JSONDecodeError, UnicodeDecodeError, huge integers
        raise MessageError(f"{what}: not valid JSON: {err}") from err
    if not isinstance(data, dict):
        raise MessageError(f"{what}: expected a JSON object, got {type(data).__name__}")
    version = data.get("v", SCHEMA_VERSION)
    if isinstance(version, bool) or version != SCHEMA_VERSION:
        raise MessageError(
            f"{what}: unsupported schema version {version!r}; this daemon speaks {SCHEMA_VERSION}"
        )
    return data


def _allowed(data: dict[str, Any], what: str, keys: set[str]) -> None:
    unknown = sorted(set(data) - keys - {"v"})
    if unknown:
        raise MessageError(f"{what}: unknown field(s) {', '.join(unknown)}")


def _number(value: Any, field: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise MessageError(f"{field}: expected a number, got {json.dumps(value)[:40]}")
    try:
        return float(value)
    except OverflowError as err:
        raise MessageError(f"{field}: number out of range") from err


def _numbers(value: Any, field: str) -> tuple[float, ...]:
    if not isinstance(value, list):
        raise MessageError(f"{field}: expected a list of numbers, got {type(value).__name__}")
    return tuple(_number(v, f"{field}[{i}]") for i, v in enumerate(value))


def _names(value: Any, field: str) -> tuple[str, ...] | None:
    if value is None:
        return None
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise MessageError(f"{field}: expected a list of joint name strings")
    return tuple(value)


def _optional_number(data: dict[str, Any], key: str, what: str) -> float | None:
    value = data.get(key)
    return None if value is None else _number(value, f"{what}.{key}")


def _bool(data: dict[str, Any], key: str, what: str, default: bool = False) -> bool:
    value = data.get(key, default)
    if not isinstance(value, bool):
        raise MessageError(f"{what}.{key}: expected true or false")
    return value


def _tolerances(value: Any, what: str) -> ToleranceMessage:
    if value is None:
        return ToleranceMessage()
    if not isinstance(value, dict):
        raise MessageError(f"{what}.tolerances: expected an object with path, goal, goal_time")
    _allowed(value, f"{what}.tolerances", {"path", "goal", "goal_time"})
    parsed: dict[str, float | tuple[float, ...] | None] = {}
    for key in ("path", "goal"):
        item = value.get(key)
        field = f"{what}.tolerances.{key}"
        parsed[key] = (
            None
            if item is None
            else _numbers(item, field)
            if isinstance(item, list)
            else _number(item, field)
        )
    goal_time = value.get("goal_time")
    return ToleranceMessage(
        path=parsed["path"],
        goal=parsed["goal"],
        goal_time=None if goal_time is None else _number(goal_time, f"{what}.tolerances.goal_time"),
    )


def decode_trajectory_goal(payload: bytes | None) -> TrajectoryGoalMessage:
    """Decode a trajectory goal: points [{positions, velocities?, accelerations?, time_from_start}]."""
    what = "trajectory goal"
    data = decode_message(payload, what)
    _allowed(data, what, {"joint_names", "points", "tolerances", "preempt", "passthrough"})
    raw_points = data.get("points")
    if not isinstance(raw_points, list):
        raise MessageError(f"{what}.points: expected a list of points")
    if len(raw_points) > MAX_TRAJECTORY_POINTS:
        raise MessageError(f"{what}.points: {len(raw_points)} points exceed {MAX_TRAJECTORY_POINTS}")
    points = []
    for i, raw in enumerate(raw_points):
        field = f"{what}.points[{i}]"
        if not isinstance(raw, dict):
            raise MessageError(f"{field}: expected an object")
        _allowed(raw, field, {"positions", "velocities", "accelerations", "time_from_start"})
        if "positions" not in raw:
            raise MessageError(f"{field}.positions: missing")
        if "time_from_start" not in raw:
            raise MessageError(f"{field}.time_from_start: missing")
        velocities = raw.get("velocities")
        accelerations = raw.get("accelerations")
        points.append(
            TrajectoryPoint(
                positions=_numbers(raw["positions"], f"{field}.positions"),
                time_from_start=_number(raw["time_from_start"], f"{field}.time_from_start"),
                velocities=None if velocities is None else _numbers(velocities, f"{field}.velocities"),
                accelerations=None
                if accelerations is None
                else _numbers(accelerations, f"{field}.accelerations"),
            )
        )
    return TrajectoryGoalMessage(
        joint_names=_names(data.get("joint_names"), f"{what}.joint_names"),
        points=tuple(points),
        tolerances=_tolerances(data.get("tolerances"), what),
        preempt=_bool(data, "preempt", what),
        passthrough=_bool(data, "passthrough", what),
    )


def decode_move_goal(payload: bytes | None) -> MoveGoalMessage:
    """Decode a move goal: positions, joint_names?, duration?, velocity_scale?, acceleration_scale?."""
    what = "move goal"
    data = decode_message(payload, what)
    _allowed(
        data,
        what,
        {
            "joint_names",
            "positions",
            "duration",
            "velocity_scale",
            "acceleration_scale",
            "tolerances",
            "preempt",
        },
    )
    if "positions" not in data:
        raise MessageError(f"{what}.positions: missing")
    velocity_scale = _optional_number(data, "velocity_scale", what)
    acceleration_scale = _optional_number(data, "acceleration_scale", what)
    return MoveGoalMessage(
        joint_names=_names(data.get("joint_names"), f"{what}.joint_names"),
        positions=_numbers(data["positions"], f"{what}.positions"),
        duration=_optional_number(data, "duration", what),
        velocity_scale=1.0 if velocity_scale is None else velocity_scale,
        acceleration_scale=1.0 if acceleration_scale is None else acceleration_scale,
        tolerances=_tolerances(data.get("tolerances"), what),
        preempt=_bool(data, "preempt", what),
    )


def decode_cancel(payload: bytes | None) -> str | None:
    """Decode a cancel request: the goal id, or None (or an empty payload) for the active goal."""
    if payload is None or len(payload) == 0:
        return None
    what = "cancel"
    data = decode_message(payload, what)
    _allowed(data, what, {"goal_id"})
    goal_id = data.get("goal_id")
    if goal_id is not None and not isinstance(goal_id, str):
        raise MessageError(f"{what}.goal_id: expected a string")
    return goal_id


def decode_stream_position(payload: bytes | None) -> StreamMessage:
    """Decode a streaming joint position command: positions, velocities?, joint_names?."""
    what = "joint_position command"
    data = decode_message(payload, what)
    _allowed(data, what, {"joint_names", "positions", "velocities"})
    if "positions" not in data:
        raise MessageError(f"{what}.positions: missing")
    velocities = data.get("velocities")
    return StreamMessage(
        joint_names=_names(data.get("joint_names"), f"{what}.joint_names"),
        positions=_numbers(data["positions"], f"{what}.positions"),
        velocities=None if velocities is None else _numbers(velocities, f"{what}.velocities"),
    )


def decode_stream_velocity(payload: bytes | None) -> StreamMessage:
    """Decode a streaming joint velocity command: velocities, joint_names?."""
    what = "joint_velocity command"
    data = decode_message(payload, what)
    _allowed(data, what, {"joint_names", "velocities"})
    if "velocities" not in data:
        raise MessageError(f"{what}.velocities: missing")
    return StreamMessage(
        joint_names=_names(data.get("joint_names"), f"{what}.joint_names"),
        positions=None,
        velocities=_numbers(data["velocities"], f"{what}.velocities"),
    )


def decode_set_io(payload: bytes | None) -> tuple[str, int, float | bool]:
    """Decode a set_io request: kind, pin, value."""
    what = "set_io"
    data = decode_message(payload, what)
    _allowed(data, what, {"kind", "pin", "value"})
    kind, pin, value = data.get("kind"), data.get("pin"), data.get("value")
    if not isinstance(kind, str):
        raise MessageError(f"{what}.kind: expected one of digital, configurable, tool, analog")
    if isinstance(pin, bool) or not isinstance(pin, int):
        raise MessageError(f"{what}.pin: expected an integer")
    if isinstance(value, bool):
        return kind, pin, value
    return kind, pin, _number(value, f"{what}.value")


def decode_set_payload(payload: bytes | None) -> tuple[float, tuple[float, float, float]]:
    """Decode a set_payload request: mass (kg), cog [x, y, z] (m)."""
    what = "set_payload"
    data = decode_message(payload, what)
    _allowed(data, what, {"mass", "cog"})
    mass = _number(data.get("mass"), f"{what}.mass")
    if not math.isfinite(mass) or mass < 0:
        raise MessageError(f"{what}.mass: must be a finite number ≥ 0, got {mass}")
    cog = _numbers(data.get("cog", [0.0, 0.0, 0.0]), f"{what}.cog")
    if len(cog) != 3 or not all(math.isfinite(c) for c in cog):
        raise MessageError(f"{what}.cog: expected three finite numbers")
    return mass, (cog[0], cog[1], cog[2])


def decode_dashboard(payload: bytes | None) -> str:
    """Decode a dashboard request: command (one line, e.g. ``power on``)."""
    what = "dashboard"
    data = decode_message(payload, what)
    _allowed(data, what, {"command"})
    command = data.get("command")
    if not isinstance(command, str) or not command.strip():
        raise MessageError(f'{what}.command: expected a dashboard command line, e.g. "power on"')
    if "\n" in command or "\r" in command or len(command) > 1024:
        raise MessageError(f"{what}.command: must be one line of at most 1024 characters")
    return command.strip()


def decode_tool_voltage(payload: bytes | None) -> int:
    """Decode a set_tool_voltage request: volts (0, 12 or 24)."""
    what = "set_tool_voltage"
    data = decode_message(payload, what)
    _allowed(data, what, {"volts"})
    volts = data.get("volts")
    if isinstance(volts, bool) or volts not in (0, 12, 24):
        raise MessageError(f"{what}.volts: must be 0, 12 or 24")
    return int(volts)


def decode_freedrive(payload: bytes | None) -> bool:
    """Decode a freedrive command: active (true keeps freedrive on for one deadman period, false ends it)."""
    what = "freedrive command"
    data = decode_message(payload, what)
    _allowed(data, what, {"active"})
    return _bool(data, "active", what, default=True)


def decode_force_mode(payload: bytes | None) -> dict[str, Any]:
    """Decode a start_force_mode request into the fields of the script command (ur-protocols.md §4.5)."""
    what = "start_force_mode"
    data = decode_message(payload, what)
    _allowed(data, what, {"task_frame", "selection", "wrench", "type", "limits", "damping", "gain_scaling"})
    fields: dict[str, Any] = {}
    for key in ("task_frame", "wrench", "limits"):
        values = _numbers(data.get(key), f"{what}.{key}")
        if len(values) != 6 or not all(math.isfinite(v) for v in values):
            raise MessageError(f"{what}.{key}: expected six finite numbers")
        fields[key] = values
    selection = data.get("selection")
    if (
        not isinstance(selection, list)
        or len(selection) != 6
        or any(v not in (0, 1) or isinstance(v, bool) for v in selection)
    ):
        raise MessageError(f"{what}.selection: expected six 0/1 values")
    fields["selection"] = tuple(int(v) for v in selection)
    force_type = data.get("type", 2)
    if isinstance(force_type, bool) or force_type not in (1, 2, 3):
        raise MessageError(f"{what}.type: must be 1, 2 or 3")
    fields["force_type"] = int(force_type)
    for key, low, high, default in (("damping", 0.0, 1.0, 0.025), ("gain_scaling", 0.0, 2.0, 0.5)):
        value = data.get(key, default)
        value = _number(value, f"{what}.{key}")
        if not low <= value <= high:
            raise MessageError(f"{what}.{key}: must be within {low}..{high}")
        fields[key] = value
    return fields


def decode_speed_slider(payload: bytes | None) -> float:
    """Decode a set_speed_slider request: fraction in [0, 1]."""
    what = "set_speed_slider"
    data = decode_message(payload, what)
    _allowed(data, what, {"fraction"})
    fraction = _number(data.get("fraction"), f"{what}.fraction")
    if not 0.0 <= fraction <= 1.0:
        raise MessageError(f"{what}.fraction: must be within 0..1, got {fraction}")
    return fraction


def decode_cycle_stats(payload: bytes | None) -> bool:
    """Decode a cycle_stats request: whether to reset the counters after reading them (default no)."""
    what = "cycle_stats"
    if payload is None or len(payload) == 0:
        return False
    data = decode_message(payload, what)
    _allowed(data, what, {"reset"})
    return _bool(data, "reset", what)


def encode_feedback(robot: str, feedback: GoalFeedback) -> bytes:
    """Encode goal feedback."""
    return encode(
        {
            "robot": robot,
            "goal_id": feedback.goal_id,
            "time_from_start": feedback.time_from_start,
            "duration": feedback.duration,
            "progress": feedback.progress,
            "desired": list(feedback.desired),
            "actual": list(feedback.actual),
            "error": list(feedback.error),
        }
    )


def encode_result(robot: str, result: GoalResult) -> bytes:
    """Encode a goal result."""
    return encode(
        {
            "robot": robot,
            "goal_id": result.goal_id,
            "status": result.status.value,
            "reason": result.reason,
            "final_positions": list(result.final_positions),
            "final_error": list(result.final_error),
            "duration": result.duration,
        }
    )


def _floats(values: Sequence[float]) -> str:
    return ",".join([_float(v) for v in values])


class JointStateEncoder:
    """Encodes a robot's joint state as JSON fast enough for 500 Hz.

    Each message is one ``%`` format of a template built once (``%r`` gives the shortest
    round-tripping text of a float, as ``repr``); only when a value is not finite (JSON has no NaN or
    inf) does it take the slow path that writes ``null`` for it.
    """

    def __init__(self, robot: str, joint_names: Sequence[str]) -> None:
        names = json.dumps(list(joint_names))
        self._head = f'{{"v":{SCHEMA_VERSION},"robot":{json.dumps(robot)},"names":{names},'
        floats = ",".join(["%r"] * len(joint_names))
        self._joints = _escape(self._head) + (
            f'"controller_time":%r,"host_time_ns":%d,"cycle":%d,"position":[{floats}],'
            f'"velocity":[{floats}],"effort":[{floats}]}}'
        )
        self._poses: dict[tuple[str, str], tuple[str, str]] = {}
        """(frame, child) → (the message's head, the whole message's ``%`` template)."""

    def encode(self, state: RobotState) -> bytes:
        """The joint_states message for ``state``."""
        positions, velocities, efforts = state.positions, state.velocities, state.efforts
        check = sum(positions) + sum(velocities) + sum(efforts) + state.controller_time
        if check - check == 0.0:  # all finite (a NaN or inf anywhere makes this NaN)
            with contextlib.suppress(TypeError):  # not as many values as joints: the slow path copes
                values = (state.controller_time, state.host_time_ns, state.cycle, *positions, *velocities)
                return (self._joints % (*values, *efforts)).encode()
        return (
            f'{self._head}"controller_time":{_float(state.controller_time)},'
            f'"host_time_ns":{state.host_time_ns},"cycle":{state.cycle},"position":[{_floats(positions)}],'
            f'"velocity":[{_floats(velocities)}],"effort":[{_floats(efforts)}]}}'
        ).encode()

    def encode_pose(self, state: RobotState, frame: str, child: str, pose: Sequence[float]) -> bytes:
        """The tcp_pose message: position and quaternion (x, y, z, w) of ``child`` in ``frame``."""
        known = self._poses.get((frame, child))
        if known is None:
            head = f'{{"v":{SCHEMA_VERSION},"frame":{json.dumps(frame)},"child":{json.dumps(child)},'
            template = _escape(head) + (
                '"controller_time":%r,"host_time_ns":%d,"position":[%r,%r,%r],"orientation":[%r,%r,%r,%r]}'
            )
            known = self._poses[(frame, child)] = (head, template)
        head, template = known
        check = sum(pose) + state.controller_time
        if len(pose) == 7 and check - check == 0.0:
            return (template % (state.controller_time, state.host_time_ns, *pose)).encode()
        return (
            f'{head}"controller_time":{_float(state.controller_time)},"host_time_ns":{state.host_time_ns},'
            f'"position":[{_floats(pose[:3])}],"orientation":[{_floats(pose[3:7])}]}}'
        ).encode()


def _escape(text: str) -> str:
    """``text`` as a literal part of a ``%`` template."""
    return text.replace("%", "%%")


def _float(value: float) -> str:
    # repr gives the shortest round-tripping text; JSON has no NaN/inf, so map them to null
    return repr(value) if value == value and value not in (math.inf, -math.inf) else "null"
