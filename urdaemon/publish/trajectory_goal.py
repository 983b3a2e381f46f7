"""The trajectory goal's message (``<cell>/<robot>/goal/trajectory``): its type, the checks of one
point and of the other fields. trajectory_json.py reads a goal's JSON a piece at a time and builds
the goal with these."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from urdaemon.control.goal_types import TrajectoryPoint
from urdaemon.errors import MessageError
from urdaemon.publish import fields
from urdaemon.publish.envelope import check_version
from urdaemon.publish.fields import ToleranceMessage

__all__ = [
    "MAX_TRAJECTORY_POINTS",
    "TRAJECTORY_FIELDS",
    "TrajectoryGoalMessage",
    "trajectory_goal",
    "trajectory_point",
]

MAX_TRAJECTORY_POINTS = 5_000
"""Most points of a trajectory goal (planning and checking are sliced, but each point costs ~60 µs)."""
TRAJECTORY_FIELDS = frozenset({"joint_names", "points", "tolerances", "preempt", "passthrough"})
"""The fields of a trajectory goal."""


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
