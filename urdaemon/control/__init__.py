"""Pure motion control: jerk-limited planning (ruckig) and the per-robot motion controller."""

from __future__ import annotations

from urdaemon.control.goal_types import GoalFeedback, GoalResult, GoalStatus, Tolerances, TrajectoryPoint
from urdaemon.control.limits import (
    check_finite,
    check_positions_within,
    check_velocities_within,
    reorder,
)
from urdaemon.control.motion_controller import ControllerStatistics, MotionController
from urdaemon.control.move import plan_move
from urdaemon.control.planned_trajectory import PlannedTrajectory
from urdaemon.control.trajectory import plan_trajectory

__all__ = [
    "ControllerStatistics",
    "GoalFeedback",
    "GoalResult",
    "GoalStatus",
    "MotionController",
    "PlannedTrajectory",
    "Tolerances",
    "TrajectoryPoint",
    "check_finite",
    "check_positions_within",
    "check_velocities_within",
    "plan_move",
    "plan_trajectory",
    "reorder",
]
