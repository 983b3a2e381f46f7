"""The one message encoding: UTF-8 JSON objects carrying ``"v": 1`` (docs/keys.md).

Decoders take what a client sent and return typed values or raise ``MessageError`` naming the
field and the problem. Range checks against a robot (limits, joint names, NaN) belong to the
controller, which rejects with its own reasons; here only the shape and types are checked.
"""

from __future__ import annotations

import contextlib
import dataclasses
import heapq
import json
import math
import re
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass
from typing import Any

from urdaemon.control.goals import GoalFeedback, GoalResult, TrajectoryPoint
from urdaemon.control.intake import MAX_JOINT_TOLERANCE
from urdaemon.control.trajectory import MAX_GOAL_TIME_S
from urdaemon.errors import MessageError
from urdaemon.model import (
    FORCE_MODE_DAMPING,
    FORCE_MODE_GAIN_SCALING,
    FORCE_MODE_TYPE,
    IO_SIZES,
    TOOL_VOLTAGES,
    RobotState,
)

Pose6 = tuple[float, float, float, float, float, float]
"""A pose: x, y, z (m) and a rotation vector (rad)."""

__all__ = [
    "CELL_GOAL_POLICIES",
    "MAX_MESSAGE_BYTES",
    "SCHEMA_VERSION",
    "SMALL_MESSAGE_BYTES",
    "CellGoalDecoder",
    "CellGoalMessage",
    "JointStateEncoder",
    "LinearGoalDecoder",
    "LinearGoalMessage",
    "MoveGoalMessage",
    "StreamMessage",
    "ToleranceMessage",
    "TrajectoryGoalMessage",
    "TwistMessage",
    "client_text",
    "decode_cancel",
    "decode_cell_cancel",
    "decode_dashboard",
    "decode_empty",
    "decode_force_mode",
    "decode_freedrive",
    "decode_lease_tokens",
    "decode_linear_goal",
    "decode_message",
    "decode_move_goal",
    "decode_set_io",
    "decode_set_payload",
    "decode_set_tcp",
    "decode_speed_slider",
    "decode_stream_position",
    "decode_stream_velocity",
    "decode_tool_voltage",
    "decode_trajectory_goal",
    "decode_twist",
    "encode",
    "encode_feedback",
    "encode_result",
    "request_body",
    "rotation_vector_of_quaternion",
    "state_time",
]

SCHEMA_VERSION = 1
SMALL_MESSAGE_BYTES = 16 * 1024
"""Largest message on every key but the trajectory goal's (moves, stream commands, services). The
largest valid one, a move of 64 joints with every field (64 names of 64 characters, 64 positions
and 64 path and goal tolerances of 24-character numbers), is 8.7 KB as compact JSON, 10.0 KB
indented; a joint position command with positions and velocities 7.7 KB. 16 KiB leaves ~1.6x room
and bounds the loop time a message within the limit can cost (garbage this size: ~0.25 ms)."""
MAX_MESSAGE_BYTES = 2 * 1024 * 1024
"""Largest trajectory goal (5 000 points with positions, velocities and accelerations: ~1.9 MB); it is
decoded and checked in slices between robot cycles (``TrajectoryGoalDecoder``)."""
MAX_TRAJECTORY_POINTS = 5_000
"""Most points of a trajectory goal (planning and checking are sliced, but each point costs ~60 µs)."""
MAX_JOINTS = 64
"""Longest list of joint values or names a message may carry (no robot has more joints)."""
MAX_NAME_CHARS = 64
"""Longest joint name accepted."""
MAX_PAYLOAD_KG = 35.0
"""Largest payload mass accepted: above every UR arm's rated payload (UR30: 30 kg)."""
MAX_COG_M = 1.0
"""Largest distance of the payload's centre of gravity from the tool flange along any axis (m)."""
MAX_FORCE_MODE = {"wrench": 1000.0, "limits": 10.0, "task_frame": 10.0}
"""Bounds of force mode's vectors: wrench (N, Nm), limits (m/s, rad/s or m, rad), task frame (m, rad)."""
POSE_FRAMES = ("base", "world")
"""The frames a pose goal or a linear goal may name (docs/keys.md); ``base`` by default."""
TWIST_FRAMES = ("base", "tool")
"""The frames a twist may be given in; ``base`` by default."""
CONFIGURATIONS = {"shoulder": ("left", "right"), "elbow": ("up", "down"), "wrist": ("up", "down")}
"""A pose goal's ``configuration``: each joint group it may name and the values it may take."""
LINEAR_LIMITS = ("speed", "acceleration", "jerk", "angular_speed", "angular_acceleration", "angular_jerk")
"""A linear goal's own Cartesian limits, each optional (m/s, m/s², m/s³, rad/s, rad/s², rad/s³)."""
MAX_LINEAR_POSES = 100
"""Most poses of one linear goal: as many as fit, with every blend radius and field, in the node's
ordinary message size (``LINEAR_MESSAGE_BYTES``); a longer path is sent as several goals."""
LINEAR_MESSAGE_BYTES = SMALL_MESSAGE_BYTES
"""Largest linear goal: the node's ordinary 16 KiB, so its JSON is parsed in one call like every other
non-trajectory message (~0.3 ms at most; 256 KiB held the loop 5-9 ms). 100 poses and 99 blend radii
of full-precision numbers with every field are ~15.6 KB as compact JSON; its poses are checked in
slices (``LinearGoalDecoder``)."""
LINEAR_POSES_PER_LOOK = 16
"""Poses of a linear goal checked between two looks at the clock (~3 µs each)."""
MAX_POSE_M = 100.0
"""Largest pose coordinate accepted (m): beyond any cell; the robot's reach is checked by IK."""
MAX_ROTATION_VECTOR = 2.0 * math.pi
"""Longest rotation vector accepted in a pose (rad): every orientation has one no longer than pi, and
2 pi leaves room for an equivalent one; longer is a mistake (degrees typed as radians, a garbage
number), refused naming the field."""
CLIENT_TEXT_CHARS = 40
"""Longest piece of a client's text (a field name, a key) echoed in a reply or a log line."""


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
    """A decoded point-to-point move goal: to joint ``positions``, or to a TCP ``pose`` (then
    ``positions`` is empty)."""

    joint_names: tuple[str, ...] | None
    positions: tuple[float, ...]
    duration: float | None
    velocity_scale: float
    acceleration_scale: float
    tolerances: ToleranceMessage
    preempt: bool
    pose: Pose6 | None = None
    """The TCP pose to reach (x, y, z m, rotation vector rad), in ``frame``; None: ``positions``."""
    frame: str = "base"
    configuration: tuple[tuple[str, str], ...] = ()
    """The wanted configuration's (joint group, value) pairs (UR models), e.g. ``(("elbow", "up"),)``."""


@dataclass(frozen=True, slots=True)
class LinearGoalMessage:
    """A decoded linear goal: straight TCP lines from the current pose through each of ``poses``."""

    poses: tuple[Pose6, ...]
    frame: str
    blend_radii: tuple[float, ...]
    """One per corner (``len(poses) - 1``), m; zeros when left out."""
    limits: tuple[tuple[str, float], ...]
    """The Cartesian limits the goal names (field, value), each > 0; the rest are the cell's defaults."""
    tolerances: ToleranceMessage


@dataclass(frozen=True, slots=True)
class TwistMessage:
    """A decoded twist command: the TCP point's velocity (m/s) and angular velocity (rad/s)."""

    linear: tuple[float, float, float]
    angular: tuple[float, float, float]
    frame: str


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


def client_text(text: str, limit: int = CLIENT_TEXT_CHARS) -> str:
    """A client's text made safe to echo: control characters escaped, at most ``limit`` characters
    (then ``…``), so no client can make a reply or a log line long or forge a line of its own."""
    short = text[: limit + 1]
    safe = "".join(c if c.isprintable() else repr(c)[1:-1] for c in short)
    return safe[:limit] + "…" if len(safe) > limit else safe


def decode_message(
    payload: bytes | bytearray | memoryview | None, what: str, *, max_bytes: int = SMALL_MESSAGE_BYTES
) -> dict[str, Any]:
    """Parse a client message into a dict, checking size (before decoding), JSON syntax, object
    shape and version."""
    if payload is None or len(payload) == 0:
        raise MessageError(f"{what}: empty message; expected a JSON object")
    if len(payload) > max_bytes:
        raise MessageError(f"{what}: message of {len(payload)} bytes exceeds the limit of {max_bytes} bytes")
    try:
        data = json.loads(bytes(payload))
    except (ValueError, RecursionError) as err:  # JSONDecodeError, UnicodeDecodeError, huge integers
        raise MessageError(f"{what}: not valid JSON: {client_text(str(err), 120)}") from err
    if not isinstance(data, dict):
        raise MessageError(f"{what}: expected a JSON object, got {type(data).__name__}")
    _check_version(data, what)
    return data


def _check_version(data: dict[str, Any], what: str) -> None:
    version = data.get("v", SCHEMA_VERSION)
    if isinstance(version, bool) or version != SCHEMA_VERSION:
        shown = client_text(repr(version))
        raise MessageError(f"{what}: unsupported schema version {shown}; this daemon speaks {SCHEMA_VERSION}")


def _shown(value: Any) -> str:
    """A client's JSON value, shortened and escaped, to say what was wrong with it."""
    try:
        return client_text(json.dumps(value)[: CLIENT_TEXT_CHARS + 1])
    except (ValueError, RecursionError):
        return type(value).__name__


def _allowed(data: dict[str, Any], what: str, keys: set[str]) -> None:
    """Refuse unknown fields, naming at most three of them, each shortened and escaped."""
    unknown = [k for k in data if k not in keys and k != "v"]
    if unknown:
        shown = ", ".join(client_text(k) for k in heapq.nsmallest(3, unknown))
        more = f" and {len(unknown) - 3} more" if len(unknown) > 3 else ""
        raise MessageError(f"{what}: unknown field(s) {shown}{more}")


def _number(value: Any, field: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise MessageError(f"{field}: expected a number, got {_shown(value)}")
    try:
        return float(value)
    except OverflowError as err:
        raise MessageError(f"{field}: number out of range") from err


def _within(value: float, field: str, low: float, high: float, *, open_low: bool = False) -> float:
    """``value`` if it lies in [low, high] (or (low, high]); else a refusal naming the range."""
    if not (value > low if open_low else value >= low) or not value <= high:
        allowed = f"> {low:g} and ≤ {high:g}" if open_low else f"within {low:g}..{high:g}"
        raise MessageError(f"{field}: must be {allowed}, got {value:g}")
    return value


def _numbers(value: Any, field: str, max_len: int = MAX_JOINTS) -> tuple[float, ...]:
    if not isinstance(value, list):
        raise MessageError(f"{field}: expected a list of numbers, got {type(value).__name__}")
    if len(value) > max_len:
        raise MessageError(f"{field}: {len(value)} values; at most {max_len} are accepted")
    return tuple(_number(v, f"{field}[{i}]") for i, v in enumerate(value))


def _names(value: Any, field: str) -> tuple[str, ...] | None:
    if value is None:
        return None
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise MessageError(f"{field}: expected a list of joint name strings")
    if len(value) > MAX_JOINTS:
        raise MessageError(f"{field}: {len(value)} names; at most {MAX_JOINTS} are accepted")
    for i, name in enumerate(value):
        if len(name) > MAX_NAME_CHARS or not name.isprintable():
            raise MessageError(
                f"{field}[{i}]: {client_text(name)!r} is not a joint name "
                f"(at most {MAX_NAME_CHARS} printable characters)"
            )
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
        if item is None:
            parsed[key] = None
        elif isinstance(item, list):
            numbers = _numbers(item, field)
            parsed[key] = tuple(
                _within(v, f"{field}[{i}]", 0.0, MAX_JOINT_TOLERANCE, open_low=True)
                for i, v in enumerate(numbers)
            )
        else:
            parsed[key] = _within(_number(item, field), field, 0.0, MAX_JOINT_TOLERANCE, open_low=True)
    goal_time = value.get("goal_time")
    field = f"{what}.tolerances.goal_time"
    return ToleranceMessage(
        path=parsed["path"],
        goal=parsed["goal"],
        goal_time=None
        if goal_time is None
        else _within(_number(goal_time, field), field, 0.0, MAX_GOAL_TIME_S),
    )


def decode_trajectory_goal(payload: bytes | None) -> TrajectoryGoalMessage:
    """Decode a trajectory goal at once (the daemon uses ``TrajectoryGoalDecoder``, in slices)."""
    from urdaemon.publish.trajectory_json import TrajectoryGoalDecoder

    decoder = TrajectoryGoalDecoder(payload)
    while decoder.step(math.inf):
        pass
    return decoder.result()


def trajectory_point(raw: Any, field: str) -> TrajectoryPoint:
    """One decoded point of a trajectory goal: {positions, velocities?, accelerations?, time_from_start}."""
    if not isinstance(raw, dict):
        raise MessageError(f"{field}: expected an object")
    _allowed(raw, field, {"positions", "velocities", "accelerations", "time_from_start"})
    if "positions" not in raw:
        raise MessageError(f"{field}.positions: missing")
    if "time_from_start" not in raw:
        raise MessageError(f"{field}.time_from_start: missing")
    velocities = raw.get("velocities")
    accelerations = raw.get("accelerations")
    return TrajectoryPoint(
        positions=_numbers(raw["positions"], f"{field}.positions"),
        time_from_start=_number(raw["time_from_start"], f"{field}.time_from_start"),
        velocities=None if velocities is None else _numbers(velocities, f"{field}.velocities"),
        accelerations=None if accelerations is None else _numbers(accelerations, f"{field}.accelerations"),
    )


TRAJECTORY_FIELDS = frozenset({"joint_names", "points", "tolerances", "preempt", "passthrough"})
"""The fields of a trajectory goal."""


def trajectory_goal(data: dict[str, Any], points: tuple[TrajectoryPoint, ...]) -> TrajectoryGoalMessage:
    """The goal from its decoded top-level fields (``points`` already decoded and checked)."""
    what = "trajectory goal"
    _check_version(data, what)
    _allowed(data, what, set(TRAJECTORY_FIELDS))
    return TrajectoryGoalMessage(
        joint_names=_names(data.get("joint_names"), f"{what}.joint_names"),
        points=points,
        tolerances=_tolerances(data.get("tolerances"), what),
        preempt=_bool(data, "preempt", what),
        passthrough=_bool(data, "passthrough", what),
    )


MOVE_FIELDS = frozenset(
    {
        "joint_names",
        "positions",
        "pose",
        "frame",
        "configuration",
        "duration",
        "velocity_scale",
        "acceleration_scale",
        "tolerances",
        "preempt",
    }
)
"""The fields of a move goal (``pose``, ``frame``, ``configuration``: a pose goal's)."""


def decode_move_goal(payload: bytes | None) -> MoveGoalMessage:
    """Decode a move goal: exactly one of positions (joints, joint_names?) or pose (the TCP, frame?,
    configuration?), and duration?, velocity_scale?, acceleration_scale?, tolerances?, preempt?."""
    what = "move goal"
    data = decode_message(payload, what)
    _allowed(data, what, set(MOVE_FIELDS))
    has_pose = data.get("pose") is not None
    if has_pose and data.get("positions") is not None:
        raise MessageError(f"{what}: give positions (joints) or pose (the TCP), not both")
    if not has_pose and "positions" not in data:
        raise MessageError(f"{what}.positions: missing")
    if not has_pose:
        for key in ("frame", "configuration"):
            if data.get(key) is not None:
                raise MessageError(f"{what}.{key}: only a pose goal has a {key} (send pose, not positions)")
    elif data.get("joint_names") is not None:
        raise MessageError(f"{what}.joint_names: a pose goal names no joints")
    velocity_scale = _optional_number(data, "velocity_scale", what)
    acceleration_scale = _optional_number(data, "acceleration_scale", what)
    for key, scale in (("velocity_scale", velocity_scale), ("acceleration_scale", acceleration_scale)):
        if scale is not None:
            _within(scale, f"{what}.{key}", 0.0, 1.0, open_low=True)
    duration = _optional_number(data, "duration", what)
    if duration is not None:
        _within(duration, f"{what}.duration", 0.0, MAX_GOAL_TIME_S, open_low=True)
    return MoveGoalMessage(
        joint_names=_names(data.get("joint_names"), f"{what}.joint_names"),
        positions=() if has_pose else _numbers(data["positions"], f"{what}.positions"),
        duration=duration,
        velocity_scale=1.0 if velocity_scale is None else velocity_scale,
        acceleration_scale=1.0 if acceleration_scale is None else acceleration_scale,
        tolerances=_tolerances(data.get("tolerances"), what),
        preempt=_bool(data, "preempt", what),
        pose=_pose(data["pose"], f"{what}.pose") if has_pose else None,
        frame=_choice(data, "frame", what, POSE_FRAMES),
        configuration=_configuration(data.get("configuration"), f"{what}.configuration"),
    )


def _pose(value: Any, field: str) -> Pose6:
    """A pose: six finite numbers, the position within ``MAX_POSE_M`` of the frame's origin, the rotation
    vector at most ``MAX_ROTATION_VECTOR`` long."""
    numbers = _numbers(value, field, max_len=6)
    if len(numbers) != 6:
        raise MessageError(f"{field}: expected six numbers [x, y, z, rx, ry, rz], got {len(numbers)}")
    for i, v in enumerate(numbers):
        if not math.isfinite(v):
            raise MessageError(f"{field}[{i}]: expected a finite number, got {v}")
    for i, v in enumerate(numbers[:3]):
        _within(v, f"{field}[{i}] (m)", -MAX_POSE_M, MAX_POSE_M)
    angle = math.hypot(numbers[3], numbers[4], numbers[5])
    if angle > MAX_ROTATION_VECTOR:
        raise MessageError(
            f"{field}[3:6] (rotation vector, rad): length {angle:.6g} is over 2 pi "
            f"({MAX_ROTATION_VECTOR:.6g}); give the axis times the angle in radians"
        )
    return (numbers[0], numbers[1], numbers[2], numbers[3], numbers[4], numbers[5])


def _choice(data: dict[str, Any], key: str, what: str, allowed: tuple[str, ...]) -> str:
    """``data[key]``, one of ``allowed`` (the first when left out or null)."""
    value = data.get(key)
    if value is None:
        return allowed[0]
    if value not in allowed:
        raise MessageError(f"{what}.{key}: expected one of {', '.join(allowed)}, got {_shown(value)}")
    return str(value)


def _configuration(value: Any, field: str) -> tuple[tuple[str, str], ...]:
    """A pose goal's configuration: any of shoulder left|right, elbow up|down, wrist up|down."""
    if value is None:
        return ()
    if not isinstance(value, dict):
        raise MessageError(f"{field}: expected an object with any of shoulder, elbow, wrist")
    _allowed(value, field, set(CONFIGURATIONS))
    chosen = []
    for group, values in CONFIGURATIONS.items():
        item = value.get(group)
        if item is None:
            continue
        if item not in values:
            raise MessageError(f"{field}.{group}: expected {' or '.join(values)}, got {_shown(item)}")
        chosen.append((group, str(item)))
    return tuple(chosen)


def decode_linear_goal(payload: bytes | None) -> LinearGoalMessage:
    """Decode a linear goal at once (the daemon uses ``LinearGoalDecoder``, in slices)."""
    decoder = LinearGoalDecoder(payload)
    while decoder.step(math.inf, lambda: 0.0):
        pass
    return decoder.result()


class LinearGoalDecoder:
    """Decodes a linear goal: poses (1..100), frame?, blend_radii?, speed?, acceleration?, jerk?,
    angular_speed?, angular_acceleration?, angular_jerk?, tolerances?.

    The JSON is parsed at once (at most ``LINEAR_MESSAGE_BYTES``, refused by size before parsing:
    ~0.3 ms); its poses are checked
    ``LINEAR_POSES_PER_LOOK`` at a time by ``step(deadline, clock)`` (True while work is left), so
    the checks of a hundred poses (~0.3 ms) run in slices between robot cycles (runtime/slicing.py).
    """

    def __init__(self, payload: bytes | None) -> None:
        what = self._what = "linear goal"
        data = decode_message(payload, what, max_bytes=LINEAR_MESSAGE_BYTES)
        _allowed(data, what, {"poses", "frame", "blend_radii", "tolerances", *LINEAR_LIMITS})
        raw = data.get("poses")
        if not isinstance(raw, list) or not raw:
            raise MessageError(f"{what}.poses: expected a list of one or more poses [x, y, z, rx, ry, rz]")
        if len(raw) > MAX_LINEAR_POSES:
            raise MessageError(f"{what}.poses: {len(raw)} poses; at most {MAX_LINEAR_POSES} are accepted")
        self._data = data
        self._raw: list[Any] = raw
        self._poses: list[Pose6] = []
        self._raw_radii: Any = None
        self._radii: list[float] | None = None
        self._result: LinearGoalMessage | None = None

    def step(self, deadline: float, clock: Callable[[], float]) -> bool:
        """Check poses, then blend radii, until ``clock()`` passes ``deadline`` (at least a few); True
        while work is left. Raises ``MessageError``."""
        while self._result is None:
            if not self._next():
                self._result = self._finish()
            elif clock() > deadline:
                return True
        return False

    def result(self) -> LinearGoalMessage:
        """The decoded goal."""
        if self._result is None:
            raise RuntimeError("the linear goal is not decoded yet")
        return self._result

    def _next(self) -> bool:
        """Check the next few poses or radii; False once all are checked."""
        raw, poses, what = self._raw, self._poses, self._what
        if len(poses) < len(raw):
            for i in range(len(poses), min(len(raw), len(poses) + LINEAR_POSES_PER_LOOK)):
                poses.append(_pose(raw[i], f"{what}.poses[{i}]"))
            return True
        field = f"{what}.blend_radii"
        if self._radii is None:
            given = self._data.get("blend_radii")
            self._raw_radii = [0.0] * (len(raw) - 1) if given is None else given
            self._radii = []
            if not isinstance(self._raw_radii, list):
                raise MessageError(f"{field}: expected a list of numbers, got {type(given).__name__}")
            if len(self._raw_radii) != len(raw) - 1:
                raise MessageError(
                    f"{field}: {len(self._raw_radii)} radii for {len(raw)} poses; expected {len(raw) - 1} "
                    "(one per corner)"
                )
        radii, given = self._radii, self._raw_radii
        if len(radii) < len(given):
            for i in range(len(radii), min(len(given), len(radii) + 6 * LINEAR_POSES_PER_LOOK)):
                radius = _number(given[i], f"{field}[{i}]")
                radii.append(_within(radius, f"{field}[{i}] (m)", 0.0, MAX_POSE_M))
            return True
        return False

    def _finish(self) -> LinearGoalMessage:
        data, what, poses = self._data, self._what, tuple(self._poses)
        limits = []
        for key in LINEAR_LIMITS:
            value = _optional_number(data, key, what)
            if value is not None:
                if not (value > 0.0 and math.isfinite(value)):
                    raise MessageError(f"{what}.{key}: must be a finite number > 0, got {value:g}")
                limits.append((key, value))
        return LinearGoalMessage(
            poses=poses,
            frame=_choice(data, "frame", what, POSE_FRAMES),
            blend_radii=tuple(self._radii or ()),
            limits=tuple(limits),
            tolerances=_tolerances(data.get("tolerances"), what),
        )


def decode_twist(payload: bytes | None) -> TwistMessage:
    """Decode a twist command: linear [3] (m/s), angular [3] (rad/s), frame? (base | tool)."""
    what = "twist command"
    data = decode_message(payload, what)
    _allowed(data, what, {"linear", "angular", "frame"})
    vectors = []
    for key in ("linear", "angular"):
        if key not in data:
            raise MessageError(f"{what}.{key}: missing")
        values = _numbers(data[key], f"{what}.{key}", max_len=3)
        if len(values) != 3 or not all(math.isfinite(v) for v in values):
            raise MessageError(f"{what}.{key}: expected three finite numbers")
        vectors.append((values[0], values[1], values[2]))
    return TwistMessage(vectors[0], vectors[1], _choice(data, "frame", what, TWIST_FRAMES))


def decode_set_tcp(payload: bytes | None) -> Pose6:
    """Decode a set_tcp request: pose [x, y, z, rx, ry, rz] (m, rad), the TCP in the tool0 frame (its
    ranges are checked by the service: cell/config.py ``check_tcp``)."""
    what = "set_tcp"
    data = decode_message(payload, what)
    _allowed(data, what, {"pose"})
    if "pose" not in data:
        raise MessageError(f"{what}.pose: missing")
    return _pose(data["pose"], f"{what}.pose")


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
    if goal_id is not None and (len(goal_id) > 200 or not goal_id.isprintable()):
        raise MessageError(f"{what}.goal_id: {client_text(goal_id)!r} is not a goal id")
    return goal_id


def decode_empty(payload: bytes | None, what: str) -> None:
    """Check the request of a service that takes no arguments: nothing, an empty payload, ``{}`` or
    ``{"v": 1}``; anything else is refused, so garbage never acts."""
    if payload is None or len(payload) == 0:
        return
    data = decode_message(payload, what)
    _allowed(data, f"{what} takes no arguments, but got", set())


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
        raise MessageError(f"{what}.kind: expected one of {', '.join(IO_SIZES)}")
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
    _within(mass, f"{what}.mass (kg)", 0.0, MAX_PAYLOAD_KG)
    cog = _numbers(data.get("cog", [0.0, 0.0, 0.0]), f"{what}.cog")
    if len(cog) != 3 or not all(math.isfinite(c) for c in cog):
        raise MessageError(f"{what}.cog: expected three finite numbers")
    for i, c in enumerate(cog):
        _within(c, f"{what}.cog[{i}] (m)", -MAX_COG_M, MAX_COG_M)
    return mass, (cog[0], cog[1], cog[2])


def decode_dashboard(payload: bytes | None) -> str:
    """Decode a dashboard request: command (one line, e.g. ``power on``)."""
    what = "dashboard"
    data = decode_message(payload, what)
    _allowed(data, what, {"command"})
    command = data.get("command")
    if not isinstance(command, str) or not command.strip():
        raise MessageError(f'{what}.command: expected a dashboard command line, e.g. "power on"')
    if not command.isprintable() or len(command) > 1024:
        raise MessageError(f"{what}.command: must be one line of at most 1024 printable characters")
    return command.strip()


def decode_tool_voltage(payload: bytes | None) -> int:
    """Decode a set_tool_voltage request: volts (0, 12 or 24)."""
    what = "set_tool_voltage"
    data = decode_message(payload, what)
    _allowed(data, what, {"volts"})
    volts = data.get("volts")
    if isinstance(volts, bool) or volts not in TOOL_VOLTAGES:
        raise MessageError(
            f"{what}.volts: must be {', '.join(map(str, TOOL_VOLTAGES[:-1]))} or {TOOL_VOLTAGES[-1]}"
        )
    return int(volts)


def decode_freedrive(payload: bytes | None) -> bool:
    """Decode a freedrive command: active (true keeps freedrive on for one deadman period, false ends it)."""
    what = "freedrive command"
    data = decode_message(payload, what)
    _allowed(data, what, {"active"})
    return _bool(data, "active", what, default=True)


def decode_force_mode(payload: bytes | None) -> dict[str, Any]:
    """Decode a start_force_mode request into the fields of the script command (docs/protocols.md §4.5)."""
    what = "start_force_mode"
    data = decode_message(payload, what)
    _allowed(data, what, {"task_frame", "selection", "wrench", "type", "limits", "damping", "gain_scaling"})
    fields: dict[str, Any] = {}
    for key in ("task_frame", "wrench", "limits"):
        values = _numbers(data.get(key), f"{what}.{key}")
        if len(values) != 6 or not all(math.isfinite(v) for v in values):
            raise MessageError(f"{what}.{key}: expected six finite numbers")
        bound = MAX_FORCE_MODE[key]
        low = 0.0 if key == "limits" else -bound
        for i, v in enumerate(values):
            _within(v, f"{what}.{key}[{i}]", low, bound)
        fields[key] = values
    selection = data.get("selection")
    if (
        not isinstance(selection, list)
        or len(selection) != 6
        or any(v not in (0, 1) or isinstance(v, bool) for v in selection)
    ):
        raise MessageError(f"{what}.selection: expected six 0/1 values")
    fields["selection"] = tuple(int(v) for v in selection)
    force_type = data.get("type", FORCE_MODE_TYPE)
    if isinstance(force_type, bool) or force_type not in (1, 2, 3):
        raise MessageError(f"{what}.type: must be 1, 2 or 3")
    fields["force_type"] = int(force_type)
    for key, low, high, default in (
        ("damping", 0.0, 1.0, FORCE_MODE_DAMPING),
        ("gain_scaling", 0.0, 2.0, FORCE_MODE_GAIN_SCALING),
    ):
        value = data.get(key, default)
        fields[key] = _within(_number(value, f"{what}.{key}"), f"{what}.{key}", low, high)
    return fields


def decode_speed_slider(payload: bytes | None) -> float:
    """Decode a set_speed_slider request: fraction in [0, 1]."""
    what = "set_speed_slider"
    data = decode_message(payload, what)
    _allowed(data, what, {"fraction"})
    return _within(_number(data.get("fraction"), f"{what}.fraction"), f"{what}.fraction", 0.0, 1.0)


def decode_cycle_stats(payload: bytes | None) -> bool:
    """Decode a cycle_stats request: whether to reset the counters after reading them (default no)."""
    what = "cycle_stats"
    if payload is None or len(payload) == 0:
        return False
    data = decode_message(payload, what)
    _allowed(data, what, {"reset"})
    return _bool(data, "reset", what)


WIRE_NAMES = {"force_type": "type"}
"""Request fields whose name in the message differs (``ForceModeRequest.force_type`` is ``type``)."""


def request_body(request: object | None) -> dict[str, Any]:
    """A service request (a dataclass of model.py, or None: no arguments) as the message's fields."""
    if request is None:
        return {}
    body: dict[str, Any] = {}
    for item in dataclasses.fields(request):  # type: ignore[arg-type]
        value = getattr(request, item.name)
        body[WIRE_NAMES.get(item.name, item.name)] = list(value) if isinstance(value, tuple) else value
    return body


def state_time(state: RobotState, now_ns: int) -> dict[str, Any]:
    """The time fields of a message about ``state``: when it arrived on the host (``host_time_ns``, Unix
    ns) and the robot's clock then (``controller_time``, s). Before any state arrived there is no robot
    clock to tell: ``host_time_ns`` is ``now_ns`` (the caller's clock; this module reads none) and
    ``controller_time`` null (docs/keys.md, "Time fields")."""
    if state.host_time_ns > 0:
        return {"host_time_ns": state.host_time_ns, "controller_time": state.controller_time}
    return {"host_time_ns": now_ns, "controller_time": None}


def encode_feedback(robot: str, feedback: GoalFeedback, stamp: dict[str, Any]) -> bytes:
    """Encode goal feedback with its time fields ``stamp`` (``state_time`` of the cycle it reports)."""
    return encode(
        {
            "robot": robot,
            **stamp,
            "goal_id": feedback.goal_id,
            "time_from_start": feedback.time_from_start,
            "duration": feedback.duration,
            "progress": feedback.progress,
            "desired": list(feedback.desired),
            "actual": list(feedback.actual),
            "error": list(feedback.error),
        }
    )


def encode_result(robot: str, result: GoalResult, stamp: dict[str, Any]) -> bytes:
    """Encode a goal result with its time fields ``stamp`` (``state_time`` of the newest state when the
    goal ended)."""
    return encode(
        {
            "robot": robot,
            **stamp,
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
        self._robot = json.dumps(robot)
        self._head = f'{{"v":{SCHEMA_VERSION},"robot":{self._robot},"names":{names},'
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
        """The tcp_pose message: the robot, and the position and quaternion (x, y, z, w) of ``child``
        in ``frame``; and the same as ``pose``, [x, y, z, rx, ry, rz] with a rotation vector, as every
        pose input takes it (``rotation_vector_of_quaternion``)."""
        known = self._poses.get((frame, child))
        if known is None:
            head = (
                f'{{"v":{SCHEMA_VERSION},"robot":{self._robot},"frame":{json.dumps(frame)},'
                f'"child":{json.dumps(child)},'
            )
            template = _escape(head) + (
                '"controller_time":%r,"host_time_ns":%d,"position":[%s],"orientation":[%r,%r,%r,%r],'
                '"pose":[%s,%r,%r,%r]}'
            )
            known = self._poses[(frame, child)] = (head, template)
        head, template = known
        check = sum(pose) + state.controller_time
        if len(pose) == 7 and check - check == 0.0:
            x, y, z, qx, qy, qz, qw = pose
            position = f"{x!r},{y!r},{z!r}"  # written once, used twice
            rx, ry, rz = rotation_vector_of_quaternion(qx, qy, qz, qw)
            stamp = (state.controller_time, state.host_time_ns)
            return (template % (*stamp, position, qx, qy, qz, qw, position, rx, ry, rz)).encode()
        rotation = rotation_vector_of_quaternion(*pose[3:7]) if len(pose) == 7 else (math.nan,) * 3
        return (
            f'{head}"controller_time":{_float(state.controller_time)},"host_time_ns":{state.host_time_ns},'
            f'"position":[{_floats(pose[:3])}],"orientation":[{_floats(pose[3:7])}],'
            f'"pose":[{_floats(pose[:3])},{_floats(rotation)}]}}'
        ).encode()


def rotation_vector_of_quaternion(qx: float, qy: float, qz: float, qw: float) -> tuple[float, float, float]:
    """The rotation vector (axis times angle, rad) of a quaternion (any length), as pose inputs take it
    (``description.frames.frame_of_pose``): the angle in [0, pi], so ``q`` and ``-q`` give the same
    vector. At exactly pi (``qw`` 0) both signs of the axis are the same turn; the one whose largest
    component is positive is given, as ``description.frames.pose_of_frame`` does. Plain float math:
    ``tcp_pose`` runs it every robot cycle."""
    s = math.hypot(qx, qy, qz)
    if s == 0.0:  # no turn (and a zero quaternion has none to tell)
        return (0.0, 0.0, 0.0)
    if qw < 0.0:  # the other half of the double cover: the same turn, the angle under pi
        qx, qy, qz, qw = -qx, -qy, -qz, -qw
    elif qw == 0.0 and _largest_negative(qx, qy, qz):
        qx, qy, qz = -qx, -qy, -qz
    k = 2.0 * math.atan2(s, qw) / s
    return (qx * k, qy * k, qz * k)


def _largest_negative(x: float, y: float, z: float) -> bool:
    """Is the component of (x, y, z) of the largest size (the first of equals) negative?"""
    ax, ay, az = abs(x), abs(y), abs(z)
    if ax >= ay and ax >= az:
        return x < 0.0
    return y < 0.0 if ay >= az else z < 0.0


def _escape(text: str) -> str:
    """``text`` as a literal part of a ``%`` template."""
    return text.replace("%", "%%")


def _float(value: float) -> str:
    # repr gives the shortest round-tripping text; JSON has no NaN/inf, so map them to null
    return repr(value) if value == value and value not in (math.inf, -math.inf) else "null"


# ---- cell goals ------------------------------------------------------------------------------------

CELL_GOAL_POLICIES = ("stop_all", "continue")
"""What a cell goal does when one robot's part ends other than succeeded: stop the others, or not."""
_CELL_GOAL = "cell goal"
_CELL_KEY_BYTES = 256
"""Longest text of a field name or a robot name in a cell goal."""
_CELL_FIELD_BYTES = 1024
"""Longest text of a cell goal's own fields (``v``, ``on_abort``)."""
_SCAN_BYTES = 64 * 1024
"""Bytes searched for the next bracket or quote in one step, when a robot's part is delimited."""
_SCAN_TOKENS = 256
"""Brackets and texts passed in one step."""
_TEXT_BYTES = 16 * 1024
"""Longest JSON text (a quoted string) inside a robot's part."""
_STRUCTURE = re.compile(rb'[][{}"]')
_STRING_REST = re.compile(rb'(?:[^"\\]++|\\.)*+"')
_SPACE = re.compile(rb"[ \t\n\r]{0,4096}")
_DONE = object()


@dataclass(frozen=True, slots=True)
class CellGoalMessage:
    """A cell goal as sent: each robot's trajectory goal body (undecoded), and the abort policy."""

    robots: dict[str, memoryview]
    on_abort: str


class CellGoalDecoder:
    """Splits a cell goal ``{"robots": {"alice": {...}, ...}, "on_abort": ...}`` into each robot's
    trajectory goal body, a piece at a time (``advance()`` until False, then ``result()``): a part
    is delimited by counting its brackets, never decoded here (each robot's own decoder does that,
    in slices too), so no step costs more than searching ``_SCAN_BYTES`` or passing
    ``_SCAN_TOKENS`` brackets. Every error is a ``MessageError``."""

    def __init__(self, payload: bytes | None, *, max_bytes: int = MAX_MESSAGE_BYTES) -> None:
        if payload is None or len(payload) == 0:
            raise MessageError(f"{_CELL_GOAL}: empty message; expected a JSON object")
        if len(payload) > max_bytes:
            raise MessageError(
                f"{_CELL_GOAL}: message of {len(payload)} bytes exceeds the limit of {max_bytes} bytes"
            )
        self._data = bytes(payload)
        self._decoder = json.JSONDecoder()
        self._steps = self._run()
        self._result: CellGoalMessage | None = None

    def advance(self) -> bool:
        """One bounded step; True while work is left (``slicing.until_deadline`` runs it in slices)."""
        return next(self._steps, _DONE) is not _DONE

    def result(self) -> CellGoalMessage:
        """The split goal."""
        if self._result is None:
            raise RuntimeError("the cell goal is not split yet")
        return self._result

    def _run(self) -> Generator[None, None, None]:
        pos = self._expect(self._space(0), b"{", "a JSON object")
        fields: dict[str, Any] = {}
        robots: dict[str, memoryview] | None = None
        if self._data.startswith(b"}", self._space(pos)):
            pos = self._space(pos) + 1
        else:
            while True:
                key, pos = self._value(pos, _CELL_KEY_BYTES, "a field name")
                if not isinstance(key, str):
                    raise MessageError(f"{_CELL_GOAL}: expected a field name at byte {pos}")
                pos = self._expect(pos, b":", "':' after a field name")
                if key == "robots":
                    robots, pos = yield from self._robots(pos)
                else:
                    fields[key], pos = self._value(pos, _CELL_FIELD_BYTES, key)
                if self._data.startswith(b",", self._space(pos)):
                    pos = self._space(pos) + 1
                    continue
                pos = self._expect(pos, b"}", "',' or '}' after a field")
                break
        if self._space(pos) != len(self._data):
            raise MessageError(f"{_CELL_GOAL}: not valid JSON: extra data at byte {self._space(pos)}")
        self._result = _cell_goal(fields, robots)

    def _robots(self, pos: int) -> Generator[None, None, tuple[dict[str, memoryview], int]]:
        pos = self._expect(pos, b"{", f"{_CELL_GOAL}.robots: an object naming each robot's trajectory")
        robots: dict[str, memoryview] = {}
        if self._data.startswith(b"}", self._space(pos)):
            return robots, self._space(pos) + 1
        while True:
            name, pos = self._value(pos, _CELL_KEY_BYTES, "a robot name")
            if not isinstance(name, str):
                raise MessageError(f"{_CELL_GOAL}.robots: expected a robot name at byte {pos}")
            what = f"{_CELL_GOAL}.robots.{client_text(name)}"
            if name in robots:
                raise MessageError(f"{what}: the robot is named twice")
            pos = self._expect(pos, b":", "':' after a robot name")
            start = self._space(pos)
            if not self._data.startswith(b"{", start):
                raise MessageError(f"{what}: expected a trajectory goal (a JSON object)")
            end = yield from self._object_end(start, what)
            robots[name] = memoryview(self._data)[start:end]
            if self._data.startswith(b",", self._space(end)):
                pos = self._space(end) + 1
                continue
            return robots, self._expect(end, b"}", "',' or '}' after a robot's trajectory")

    def _object_end(self, pos: int, what: str) -> Generator[None, None, int]:
        """Where the object at ``pos`` ends: its brackets counted, quoted texts passed over."""
        data, depth, passed = self._data, 0, 0
        while True:
            found = _STRUCTURE.search(data, pos, pos + _SCAN_BYTES)
            if found is None:
                if pos + _SCAN_BYTES >= len(data):
                    raise MessageError(f"{what}: not valid JSON: the object does not end")
                pos += _SCAN_BYTES
                yield None
                continue
            char, pos = data[found.start()], found.end()
            if char == 0x22:  # a quoted text: passed over whole, brackets in it do not count
                text = _STRING_REST.match(data, pos, pos + _TEXT_BYTES)
                if text is None:
                    raise MessageError(
                        f"{what}: a text at byte {pos} is unterminated or over {_TEXT_BYTES} bytes"
                    )
                pos = text.end()
            elif char in b"{[":
                depth += 1
            else:
                depth -= 1
                if depth == 0:
                    return pos
            passed += 1
            if passed % _SCAN_TOKENS == 0:
                yield None

    def _value(self, pos: int, limit: int, what: str) -> tuple[Any, int]:
        """One JSON value of at most ``limit`` bytes at ``pos`` (after whitespace), and the byte after it."""
        pos = self._space(pos)
        window = self._data[pos : pos + limit]
        try:
            text = window.decode()
        except UnicodeDecodeError as err:
            if err.end < len(window) or pos + limit >= len(self._data):  # not a character cut short
                raise MessageError(f"{_CELL_GOAL}: not valid JSON: not UTF-8 text ({err.reason})") from err
            text = window[: err.start].decode()
        try:
            value, end = self._decoder.raw_decode(text)
        except (ValueError, RecursionError) as err:
            raise MessageError(
                f"{_CELL_GOAL}: not valid JSON: {what} at byte {pos} is malformed or over {limit} bytes"
            ) from err
        return value, pos + len(text[:end].encode())

    def _space(self, pos: int) -> int:
        found = _SPACE.match(self._data, pos)
        return pos if found is None else found.end()

    def _expect(self, pos: int, char: bytes, what: str) -> int:
        pos = self._space(pos)
        if not self._data.startswith(char, pos):
            raise MessageError(f"{_CELL_GOAL}: not valid JSON: expected {what} at byte {pos}")
        return pos + 1


def _cell_goal(fields: dict[str, Any], robots: dict[str, memoryview] | None) -> CellGoalMessage:
    _check_version(fields, _CELL_GOAL)
    _allowed(fields, _CELL_GOAL, {"on_abort"})
    if not robots:
        raise MessageError(f"{_CELL_GOAL}.robots: expected an object naming at least one robot's trajectory")
    on_abort = fields.get("on_abort", CELL_GOAL_POLICIES[0])
    if on_abort not in CELL_GOAL_POLICIES:
        raise MessageError(
            f"{_CELL_GOAL}.on_abort: expected one of {', '.join(CELL_GOAL_POLICIES)}, got {_shown(on_abort)}"
        )
    return CellGoalMessage(robots, on_abort)


def decode_cell_cancel(payload: bytes | None) -> str:
    """Decode a cell goal's cancel: ``{"goal_id": G}`` (the id is required)."""
    goal_id = decode_cancel(payload)
    if goal_id is None:
        raise MessageError("cell cancel.goal_id: required (the cell goal's id)")
    return goal_id


def decode_lease_tokens(attachment: bytes | None, limit: int = SMALL_MESSAGE_BYTES) -> dict[str, bytes]:
    """A cell request's attachment: each robot's lease token, ``{"alice": T, ...}`` (empty: none)."""
    if attachment is None or len(attachment) == 0:
        return {}
    if len(attachment) > limit:
        raise MessageError(f"lease tokens: attachment of {len(attachment)} bytes exceeds {limit} bytes")
    try:
        data = json.loads(attachment)
    except (ValueError, RecursionError) as err:
        raise MessageError("lease tokens: the attachment is not a JSON object of robot tokens") from err
    if not isinstance(data, dict) or not all(isinstance(v, str) for v in data.values()):
        raise MessageError('lease tokens: the attachment must be a JSON object {"<robot>": "<token>", ...}')
    # a token that is not ASCII is no holder's token: kept (as one that matches none), so the robot
    # it names is still checked and refused naming its lease
    return {name: token.encode() if token.isascii() else b"" for name, token in data.items()}
