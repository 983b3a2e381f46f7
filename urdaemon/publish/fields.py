"""The checks of a decoded message's fields that every request decoder shares.

Each takes a field's JSON value and the field's name (``move goal.positions``), and returns the typed
value or raises ``MessageError`` naming the field and the problem. Range checks against a robot
(limits, joint names, NaN) belong to the controller, which rejects with its own reasons; here only
the shape and types are checked, and bounds no valid message reaches.
"""

from __future__ import annotations

import heapq
import json
import math
from dataclasses import dataclass
from typing import Any

from urdaemon.control.intake import MAX_JOINT_TOLERANCE
from urdaemon.control.trajectory import MAX_GOAL_TIME_S
from urdaemon.errors import MessageError
from urdaemon.publish.envelope import CLIENT_TEXT_CHARS, client_text

__all__ = [
    "MAX_JOINTS",
    "MAX_NAME_CHARS",
    "MAX_POSE_M",
    "MAX_ROTATION_VECTOR",
    "POSE_FRAMES",
    "Pose6",
    "ToleranceMessage",
    "allowed",
    "boolean",
    "choice",
    "joint_names",
    "number",
    "numbers",
    "optional_number",
    "pose",
    "shown",
    "tolerances",
    "within",
]

Pose6 = tuple[float, float, float, float, float, float]
"""A pose: x, y, z (m) and a rotation vector (rad)."""

MAX_JOINTS = 64
"""Longest list of joint values or names a message may carry (no robot has more joints)."""
MAX_NAME_CHARS = 64
"""Longest joint name accepted."""
POSE_FRAMES = ("base", "world")
"""The frames a pose goal or a linear goal may name (docs/keys.md); ``base`` by default."""
MAX_POSE_M = 100.0
"""Largest pose coordinate accepted (m): beyond any cell; the robot's reach is checked by IK."""
MAX_ROTATION_VECTOR = 2.0 * math.pi
"""Longest rotation vector accepted in a pose (rad): every orientation has one no longer than pi, and
2 pi leaves room for an equivalent one; longer is a mistake (degrees typed as radians, a garbage
number), refused naming the field."""


@dataclass(frozen=True, slots=True)
class ToleranceMessage:
    """Tolerances as sent: a number for every joint, or one per joint in the goal's joint order."""

    path: float | tuple[float, ...] | None = None
    goal: float | tuple[float, ...] | None = None
    goal_time: float | None = None


def shown(value: Any) -> str:
    """A client's JSON value, shortened and escaped, to say what was wrong with it."""
    try:
        return client_text(json.dumps(value)[: CLIENT_TEXT_CHARS + 1])
    except (ValueError, RecursionError):
        return type(value).__name__


def allowed(data: dict[str, Any], what: str, keys: set[str]) -> None:
    """Refuse unknown fields, naming at most three of them, each shortened and escaped."""
    unknown = [k for k in data if k not in keys and k != "v"]
    if unknown:
        listed = ", ".join(client_text(k) for k in heapq.nsmallest(3, unknown))
        more = f" and {len(unknown) - 3} more" if len(unknown) > 3 else ""
        raise MessageError(f"{what}: unknown field(s) {listed}{more}")


def number(value: Any, field: str) -> float:
    """A JSON number (not a boolean) as a float."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise MessageError(f"{field}: expected a number, got {shown(value)}")
    try:
        return float(value)
    except OverflowError as err:
        raise MessageError(f"{field}: number out of range") from err


def within(value: float, field: str, low: float, high: float, *, open_low: bool = False) -> float:
    """``value`` if it lies in [low, high] (or (low, high]); else a refusal naming the range."""
    if not (value > low if open_low else value >= low) or not value <= high:
        bounds = f"> {low:g} and ≤ {high:g}" if open_low else f"within {low:g}..{high:g}"
        raise MessageError(f"{field}: must be {bounds}, got {value:g}")
    return value


def numbers(value: Any, field: str, max_len: int = MAX_JOINTS) -> tuple[float, ...]:
    """A list of at most ``max_len`` numbers."""
    if not isinstance(value, list):
        raise MessageError(f"{field}: expected a list of numbers, got {type(value).__name__}")
    if len(value) > max_len:
        raise MessageError(f"{field}: {len(value)} values; at most {max_len} are accepted")
    return tuple(number(v, f"{field}[{i}]") for i, v in enumerate(value))


def joint_names(value: Any, field: str) -> tuple[str, ...] | None:
    """A list of joint names (None: left out)."""
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


def optional_number(data: dict[str, Any], key: str, what: str) -> float | None:
    """``data[key]`` as a number, or None when left out or null."""
    value = data.get(key)
    return None if value is None else number(value, f"{what}.{key}")


def boolean(data: dict[str, Any], key: str, what: str, default: bool = False) -> bool:
    """``data[key]``, true or false (``default`` when left out)."""
    value = data.get(key, default)
    if not isinstance(value, bool):
        raise MessageError(f"{what}.{key}: expected true or false")
    return value


def tolerances(value: Any, what: str) -> ToleranceMessage:
    """A goal's tolerances: path and goal (a number, or one per joint), goal_time (s)."""
    if value is None:
        return ToleranceMessage()
    if not isinstance(value, dict):
        raise MessageError(f"{what}.tolerances: expected an object with path, goal, goal_time")
    allowed(value, f"{what}.tolerances", {"path", "goal", "goal_time"})
    parsed: dict[str, float | tuple[float, ...] | None] = {}
    for key in ("path", "goal"):
        item = value.get(key)
        field = f"{what}.tolerances.{key}"
        if item is None:
            parsed[key] = None
        elif isinstance(item, list):
            values = numbers(item, field)
            parsed[key] = tuple(
                within(v, f"{field}[{i}]", 0.0, MAX_JOINT_TOLERANCE, open_low=True)
                for i, v in enumerate(values)
            )
        else:
            parsed[key] = within(number(item, field), field, 0.0, MAX_JOINT_TOLERANCE, open_low=True)
    goal_time = value.get("goal_time")
    field = f"{what}.tolerances.goal_time"
    return ToleranceMessage(
        path=parsed["path"],
        goal=parsed["goal"],
        goal_time=None
        if goal_time is None
        else within(number(goal_time, field), field, 0.0, MAX_GOAL_TIME_S),
    )


def pose(value: Any, field: str) -> Pose6:
    """A pose: six finite numbers, the position within ``MAX_POSE_M`` of the frame's origin, the rotation
    vector at most ``MAX_ROTATION_VECTOR`` long."""
    values = numbers(value, field, max_len=6)
    if len(values) != 6:
        raise MessageError(f"{field}: expected six numbers [x, y, z, rx, ry, rz], got {len(values)}")
    for i, v in enumerate(values):
        if not math.isfinite(v):
            raise MessageError(f"{field}[{i}]: expected a finite number, got {v}")
    for i, v in enumerate(values[:3]):
        within(v, f"{field}[{i}] (m)", -MAX_POSE_M, MAX_POSE_M)
    angle = math.hypot(values[3], values[4], values[5])
    if angle > MAX_ROTATION_VECTOR:
        raise MessageError(
            f"{field}[3:6] (rotation vector, rad): length {angle:.6g} is over 2 pi "
            f"({MAX_ROTATION_VECTOR:.6g}); give the axis times the angle in radians"
        )
    return (values[0], values[1], values[2], values[3], values[4], values[5])


def choice(data: dict[str, Any], key: str, what: str, options: tuple[str, ...]) -> str:
    """``data[key]``, one of ``options`` (the first when left out or null)."""
    value = data.get(key)
    if value is None:
        return options[0]
    if value not in options:
        raise MessageError(f"{what}.{key}: expected one of {', '.join(options)}, got {shown(value)}")
    return str(value)
