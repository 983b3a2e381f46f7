"""The trajectory goal's message (``<cell>/<robot>/goal/trajectory``): the goal as a client sends it
(``TrajectoryGoalRequest``, ``trajectory_goal_body``), its decoded type, the checks of one point and
of the other fields. trajectory_json.py reads a goal's JSON a piece at a time and builds the goal
with these."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from urdaemon.control.goal_types import TrajectoryPoint
from urdaemon.errors import MessageError
from urdaemon.publish import fields
from urdaemon.publish.envelope import check_version, message_body
from urdaemon.publish.fields import ToleranceMessage

__all__ = [
    "MAX_TRAJECTORY_POINTS",
    "TRAJECTORY_FIELDS",
    "TrajectoryGoalMessage",
    "TrajectoryGoalRequest",
    "trajectory_goal",
    "trajectory_goal_body",
    "trajectory_point",
]

MAX_TRAJECTORY_POINTS = 5_000
"""Most points of a trajectory goal (planning and checking are sliced, but each point costs ~60 µs)."""


@dataclass(frozen=True, slots=True)
class TrajectoryGoalRequest:
    """A trajectory goal as a client sends it (a robot's, or one robot's part of a cell goal). Each
    field is the message's field of that name, in this order; None is left out (the daemon's
    default), and so is ``passthrough`` unless True. Values go as given: the daemon checks them and
    refuses naming the field."""

    points: tuple[dict[str, Any], ...]
    """Each point: ``positions``, ``velocities``?, ``accelerations``?, ``time_from_start`` (s)."""
    preempt: bool | None = None
    passthrough: bool = False
    """Forward the points to the robot, which interpolates them itself (UR controllers only)."""
    joint_names: tuple[str, ...] | None = None
    tolerances: dict[str, Any] | None = None
    """``path``, ``goal`` (a number, or one per joint), ``goal_time`` (s)."""


TRAJECTORY_FIELDS = frozenset(item.name for item in dataclasses.fields(TrajectoryGoalRequest))
"""The fields of a trajectory goal."""


def trajectory_goal_body(request: TrajectoryGoalRequest) -> dict[str, Any]:
    """The message's fields of ``request`` (the trajectory decoder's inverse): tuples as lists, None
    left out, ``passthrough`` only when True."""
    body = message_body(request)
    if not request.passthrough:
        del body["passthrough"]
    return body


@dataclass(frozen=True, slots=True)
class TrajectoryGoalMessage:
    """A decoded trajectory goal."""

    joint_names: tuple[str, ...] | None
    points: tuple[TrajectoryPoint, ...]
    tolerances: ToleranceMessage
    preempt: bool
    passthrough: bool = False
    """Forward the points to the robot, which interpolates them itself (UR controllers only)."""


def trajectory_point(raw: Any, field: str) -> TrajectoryPoint:
    """One decoded point of a trajectory goal: {positions, velocities?, accelerations?, time_from_start}."""
    if not isinstance(raw, dict):
        raise MessageError(f"{field}: expected an object")
    fields.allowed(raw, field, {"positions", "velocities", "accelerations", "time_from_start"})
    if "positions" not in raw:
        raise MessageError(f"{field}.positions: missing")
    if "time_from_start" not in raw:
        raise MessageError(f"{field}.time_from_start: missing")
    velocities = raw.get("velocities")
    accelerations = raw.get("accelerations")
    return TrajectoryPoint(
        positions=fields.numbers(raw["positions"], f"{field}.positions"),
        time_from_start=fields.number(raw["time_from_start"], f"{field}.time_from_start"),
        velocities=None if velocities is None else fields.numbers(velocities, f"{field}.velocities"),
        accelerations=None
        if accelerations is None
        else fields.numbers(accelerations, f"{field}.accelerations"),
    )


def trajectory_goal(data: dict[str, Any], points: tuple[TrajectoryPoint, ...]) -> TrajectoryGoalMessage:
    """The goal from its decoded top-level fields (``points`` already decoded and checked)."""
    what = "trajectory goal"
    check_version(data, what)
    fields.allowed(data, what, set(TRAJECTORY_FIELDS))
    return TrajectoryGoalMessage(
        joint_names=fields.joint_names(data.get("joint_names"), f"{what}.joint_names"),
        points=points,
        tolerances=fields.tolerances(data.get("tolerances"), what),
        preempt=fields.boolean(data, "preempt", what),
        passthrough=fields.boolean(data, "passthrough", what),
    )
