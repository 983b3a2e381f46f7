"""The move goal's message (``<cell>/<robot>/goal/move``): point to point, to joint positions or to a
TCP pose; the goal as a client sends it (``MoveGoalRequest``, ``move_goal_body``), its decoded type
and its decoder."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from urdaemon.control.trajectory import MAX_GOAL_TIME_S
from urdaemon.errors import MessageError
from urdaemon.publish import fields
from urdaemon.publish.envelope import decode_message, message_body
from urdaemon.publish.fields import POSE_FRAMES, Pose6, ToleranceMessage

__all__ = [
    "CONFIGURATIONS",
    "MOVE_FIELDS",
    "MoveGoalMessage",
    "MoveGoalRequest",
    "decode_move_goal",
    "move_goal_body",
]

CONFIGURATIONS = {"shoulder": ("left", "right"), "elbow": ("up", "down"), "wrist": ("up", "down")}
"""A pose goal's ``configuration``: each joint group it may name and the values it may take."""


@dataclass(frozen=True, slots=True)
class MoveGoalRequest:
    """A move goal as a client sends it: to joint ``positions``, or to a TCP ``pose`` (with ``frame``
    and ``configuration``, a pose goal's only). Each field is the message's field of that name, in
    this order; None is left out (the daemon's default). Values go as given: the daemon checks them
    and refuses naming the field."""

    positions: tuple[float, ...] | None = None
    pose: tuple[float, ...] | None = None
    frame: str | None = None
    velocity_scale: float | None = None
    acceleration_scale: float | None = None
    preempt: bool | None = None
    configuration: dict[str, str] | None = None
    """Joint group → value (``{"elbow": "up"}``, ``CONFIGURATIONS``)."""
    duration: float | None = None
    joint_names: tuple[str, ...] | None = None
    tolerances: dict[str, Any] | None = None
    """``path``, ``goal`` (a number, or one per joint), ``goal_time`` (s)."""


MOVE_FIELDS = frozenset(item.name for item in dataclasses.fields(MoveGoalRequest))
"""The fields of a move goal (``pose``, ``frame``, ``configuration``: a pose goal's)."""


def move_goal_body(request: MoveGoalRequest) -> dict[str, Any]:
    """The message's fields of ``request`` (``decode_move_goal``'s inverse): tuples as lists, None
    left out."""
    return message_body(request)


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


def decode_move_goal(payload: bytes | None) -> MoveGoalMessage:
    """Decode a move goal: exactly one of positions (joints, joint_names?) or pose (the TCP, frame?,
    configuration?), and duration?, velocity_scale?, acceleration_scale?, tolerances?, preempt?."""
    what = "move goal"
    data = decode_message(payload, what)
    fields.allowed(data, what, set(MOVE_FIELDS))
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
    velocity_scale = fields.optional_number(data, "velocity_scale", what)
    acceleration_scale = fields.optional_number(data, "acceleration_scale", what)
    for key, scale in (("velocity_scale", velocity_scale), ("acceleration_scale", acceleration_scale)):
        if scale is not None:
            fields.within(scale, f"{what}.{key}", 0.0, 1.0, open_low=True)
    duration = fields.optional_number(data, "duration", what)
    if duration is not None:
        fields.within(duration, f"{what}.duration", 0.0, MAX_GOAL_TIME_S, open_low=True)
    return MoveGoalMessage(
        joint_names=fields.joint_names(data.get("joint_names"), f"{what}.joint_names"),
        positions=() if has_pose else fields.numbers(data["positions"], f"{what}.positions"),
        duration=duration,
        velocity_scale=1.0 if velocity_scale is None else velocity_scale,
        acceleration_scale=1.0 if acceleration_scale is None else acceleration_scale,
        tolerances=fields.tolerances(data.get("tolerances"), what),
        preempt=fields.boolean(data, "preempt", what),
        pose=fields.pose(data["pose"], f"{what}.pose") if has_pose else None,
        frame=fields.choice(data, "frame", what, POSE_FRAMES),
        configuration=_configuration(data.get("configuration"), f"{what}.configuration"),
    )


def _configuration(value: Any, field: str) -> tuple[tuple[str, str], ...]:
    """A pose goal's configuration: any of shoulder left|right, elbow up|down, wrist up|down."""
    if value is None:
        return ()
    if not isinstance(value, dict):
        raise MessageError(f"{field}: expected an object with any of shoulder, elbow, wrist")
    fields.allowed(value, field, set(CONFIGURATIONS))
    chosen = []
    for group, values in CONFIGURATIONS.items():
        item = value.get(group)
        if item is None:
            continue
        if item not in values:
            raise MessageError(f"{field}.{group}: expected {' or '.join(values)}, got {fields.shown(item)}")
        chosen.append((group, str(item)))
    return tuple(chosen)
