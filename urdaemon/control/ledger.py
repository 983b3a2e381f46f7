"""The controller's ledger: goals opened and closed, what waits to be drained, and the counters.

Owns the feedback and results emitted since the last drain (one list, which the running goal appends
its feedback to), the counters reported as ``ControllerStatistics``, and the plans of ended goals,
freed ``RELEASE_SEGMENTS`` a cycle so that letting go of a long plan never holds the loop. Opening a
goal makes its run with what every run shares (the setpoint, the period, the feedback period).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from urdaemon.control.goal_run import GoalRun
from urdaemon.control.goal_types import GoalFeedback, GoalResult, GoalStatus
from urdaemon.control.intake import GoalTolerances
from urdaemon.control.planned_trajectory import PlannedTrajectory
from urdaemon.control.setpoint import Setpoint

__all__ = ["RELEASE_SEGMENTS", "ControllerStatistics", "GoalLedger"]

RELEASE_SEGMENTS = 64
"""Segments of a finished goal's plan freed per tick (~20 µs): freeing a 5 000-point plan at once
would hold the loop for ~1.5 ms."""


@dataclass(frozen=True, slots=True)
class ControllerStatistics:
    """Counters since the controller was created."""

    ticks: int
    goals_accepted: int
    goals_succeeded: int
    goals_aborted: int
    goals_canceled: int
    goals_preempted: int
    stream_commands: int
    deadman_stops: int


class GoalLedger:
    """Opens and closes goal runs, keeps their events until drained, counts, frees ended plans."""

    __slots__ = (
        "_ended",
        "_feedback_period",
        "_names",
        "_period",
        "_setpoint",
        "accepted",
        "deadman_stops",
        "events",
        "released",
        "stream_commands",
    )

    def __init__(
        self, setpoint: Setpoint, *, period: float, feedback_period: float, names: tuple[str, ...]
    ) -> None:
        self._setpoint = setpoint
        self._period = period
        self._feedback_period = feedback_period
        self._names = names
        self.events: list[GoalFeedback | GoalResult] = []
        """Feedback and results not drained yet, oldest first (never replaced: runs hold it)."""
        self.released: list[PlannedTrajectory] = []
        """Plans of ended goals still being freed, a few segments a tick."""
        self.accepted = 0
        self._ended = dict.fromkeys(GoalStatus, 0)
        self.stream_commands = 0
        self.deadman_stops = 0

    def open(self, goal_id: str, plan: PlannedTrajectory, tolerances: GoalTolerances) -> GoalRun:
        """The run of a goal accepted now."""
        self.accepted += 1
        return GoalRun(
            goal_id,
            plan,
            tolerances,
            self._setpoint,
            self.events,
            period=self._period,
            feedback_period=self._feedback_period,
            names=self._names,
        )

    def close(self, run: GoalRun, status: GoalStatus, reason: str, measured: Sequence[float]) -> None:
        """Record how ``run`` ended with the robot at ``measured``: its result, the count, its plan."""
        if run.plan.segment_count > RELEASE_SEGMENTS:
            self.released.append(run.plan)  # freed over the next ticks, not all at once here
        self.events.append(run.result(status, reason, measured))
        self._ended[status] += 1

    def release_some(self) -> None:
        """Free a few segments of an ended goal's plan (the last ended first)."""
        released = self.released
        if not released[-1].release(RELEASE_SEGMENTS):
            released.pop()

    def drain(self) -> list[GoalFeedback | GoalResult]:
        """The events since the last drain, oldest first; the ledger's list is emptied, not replaced."""
        events = self.events.copy()
        self.events.clear()
        return events

    def statistics(self, ticks: int) -> ControllerStatistics:
        """A snapshot of the counters, with ``ticks`` (the controller counts those itself)."""
        ended = self._ended
        return ControllerStatistics(
            ticks=ticks,
            goals_accepted=self.accepted,
            goals_succeeded=ended[GoalStatus.SUCCEEDED],
            goals_aborted=ended[GoalStatus.ABORTED],
            goals_canceled=ended[GoalStatus.CANCELED],
            goals_preempted=ended[GoalStatus.PREEMPTED],
            stream_commands=self.stream_commands,
            deadman_stops=self.deadman_stops,
        )
