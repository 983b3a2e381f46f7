"""Value types exchanged with the motion controller: trajectory points, tolerances, feedback, results."""

from __future__ import annotations

import enum
from dataclasses import dataclass

__all__ = ["GoalFeedback", "GoalResult", "GoalStatus", "Tolerances", "TrajectoryPoint"]


class GoalStatus(enum.StrEnum):
    """How an accepted goal ended; every accepted goal ends with exactly one of these."""

    SUCCEEDED = "succeeded"
    ABORTED = "aborted"
    CANCELED = "canceled"
    PREEMPTED = "preempted"


@dataclass(frozen=True, slots=True)
class TrajectoryPoint:
    """One waypoint: joint values in the sender's joint order, reached ``time_from_start`` s into the goal."""

    positions: tuple[float, ...]
    time_from_start: float
    velocities: tuple[float, ...] | None = None
    accelerations: tuple[float, ...] | None = None


@dataclass(frozen=True, slots=True)
class Tolerances:
    """Per-goal tolerances, per joint in controller joint order; ``None`` selects the controller default."""

    path: tuple[float, ...] | None = None
    goal: tuple[float, ...] | None = None
    goal_time: float | None = None
    """Seconds allowed after the planned end to get every joint within its goal tolerance."""


@dataclass(frozen=True, slots=True)
class GoalFeedback:
    """Progress of the executing goal; ``error`` is ``desired - actual`` per joint."""

    goal_id: str
    time_from_start: float
    duration: float
    desired: tuple[float, ...]
    actual: tuple[float, ...]
    error: tuple[float, ...]

    @property
    def progress(self) -> float:
        """Fraction of the planned trajectory time executed, in [0, 1]."""
        if self.duration <= 0.0:
            return 1.0
        return min(1.0, max(0.0, self.time_from_start / self.duration))


@dataclass(frozen=True, slots=True)
class GoalResult:
    """How a goal ended; ``final_error`` = setpoint − measured then, ``duration`` = trajectory time run."""

    goal_id: str
    status: GoalStatus
    reason: str
    final_positions: tuple[float, ...]
    final_error: tuple[float, ...]
    duration: float
