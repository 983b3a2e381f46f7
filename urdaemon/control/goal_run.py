"""One executing goal: its plan sampled on trajectory time, its tolerances, feedback, end and result.

Owns what one accepted goal needs while it runs: the plan, the trajectory time reached (advanced by the
goal's time scaling, which follows the robot's speed scaling), the path and goal tolerances with the
checks of every cycle, the feedback due, the check at the planned end, and the goal's result. It writes
the setpoint it samples into the setpoint's lists; ending it (a stop, a hold, idle) is the controller's.
A passthrough goal is one too: the robot interpolates it, so it only estimates the progress for
feedback and checks the robot's reported end against the goal tolerance.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

from urdaemon.control.goal_types import GoalFeedback, GoalResult, GoalStatus
from urdaemon.control.intake import GoalTolerances
from urdaemon.control.planned_trajectory import PlannedTrajectory
from urdaemon.control.setpoint import Setpoint, write_idle
from urdaemon.model import CommandMode, JointCommand, RobotState

__all__ = ["GoalEnd", "GoalRun"]

_END_EPS = 1e-9
"""Trajectory time that counts as "at the end" despite float accumulation of period × scaling."""
_POSITION = CommandMode.POSITION


class GoalEnd(NamedTuple):
    """How a goal ended in a cycle, and whether a stop ramp follows."""

    status: GoalStatus
    reason: str
    ramp: bool
    """False: the robot does not follow the setpoint, so the controller goes idle without a ramp."""


class GoalRun:
    """The executing goal: samples its plan into the setpoint each cycle and checks its tolerances."""

    __slots__ = (
        "_acc",
        "_events",
        "_feedback_period",
        "_names",
        "_pacc",
        "_period",
        "_pos",
        "_pvel",
        "_scaling",
        "_vel",
        "_zeros",
        "duration",
        "end_now",
        "final",
        "goal_id",
        "goal_time",
        "goal_tol",
        "next_feedback",
        "path_tol",
        "plan",
        "t",
    )

    def __init__(
        self,
        goal_id: str,
        plan: PlannedTrajectory,
        tolerances: GoalTolerances,
        setpoint: Setpoint,
        events: list[GoalFeedback | GoalResult],
        *,
        period: float,
        feedback_period: float,
        names: tuple[str, ...],
    ) -> None:
        self.goal_id = goal_id
        self.plan = plan
        self.duration = plan.duration
        self.final = plan.final_positions
        self.path_tol = tolerances.path
        self.goal_tol = tolerances.goal
        self.goal_time = tolerances.goal_time
        self.t = 0.0
        """Trajectory time reached (s)."""
        self.end_now: float | None = None
        """When the planned end was reached (host seconds)."""
        self.next_feedback = -math.inf
        self._events = events
        self._period = period
        self._feedback_period = feedback_period
        self._names = names
        self._pos = setpoint.pos
        self._vel = setpoint.vel
        self._acc = setpoint.acc
        self._pvel = setpoint.pvel
        self._pacc = setpoint.pacc
        self._scaling = setpoint.scaling
        self._zeros = setpoint.zeros

    def tick(self, state: RobotState, command: JointCommand, now: float) -> GoalEnd | None:
        """One cycle: check, feed back, advance and write the setpoint; how it ended, or None."""
        meas = state.positions
        pos = self._pos
        n = len(pos)
        # The robot lags one cycle, so compare it with the setpoint commanded last cycle.
        path_tol = self.path_tol
        for i in range(n):
            err = pos[i] - meas[i]
            if err > path_tol[i] or -err > path_tol[i]:
                reason = (
                    f"path tolerance violated: {self._names[i]} is {err:.4g} from its setpoint, "
                    f"tolerance {path_tol[i]:.4g}"
                )
                return GoalEnd(GoalStatus.ABORTED, reason, ramp=False)
        if now >= self.next_feedback:
            self._feedback(pos, meas, now)
        if self.t >= self.duration:
            ended = self._end_check(meas, now)
            if ended is not None:
                return ended
            # Holding the final point: the setpoint stays as it is.
        else:
            scaling = self._scaling
            s = scaling.value
            if s == state.speed_scaling and scaling.rate == 0.0:
                t = self.t + self._period * s
            else:
                t = self.t + scaling.advance(state.speed_scaling)
                s = scaling.value
            if t >= self.duration - _END_EPS:
                t = self.duration
                self.end_now = now
            self.t = t
            self.plan.sample(t, pos, self._pvel, self._pacc)
            if s == 1.0:
                self._vel[:] = self._pvel
            else:
                vel = self._vel
                pvel = self._pvel
                for i in range(n):
                    vel[i] = pvel[i] * s
        command.mode = _POSITION
        command.positions[:] = pos
        command.velocities[:] = self._vel
        return None

    def _end_check(self, meas: Sequence[float], now: float) -> GoalEnd | None:
        """Past the planned end: success within the goal tolerance, an abort after the goal time."""
        if self.end_now is None:
            self.end_now = now
        final = self.final
        goal_tol = self.goal_tol
        worst = -1
        for i in range(len(final)):
            if abs(final[i] - meas[i]) > goal_tol[i]:
                worst = i
                break
        if worst < 0:
            return GoalEnd(GoalStatus.SUCCEEDED, "reached the goal within tolerance", ramp=True)
        if now - self.end_now > self.goal_time:
            err = final[worst] - meas[worst]
            reason = (
                f"goal tolerance not reached {self.goal_time:.4g} s after the planned end: "
                f"{self._names[worst]} is {err:.4g} from its goal, tolerance {goal_tol[worst]:.4g}"
            )
            return GoalEnd(GoalStatus.ABORTED, reason, ramp=True)
        return None

    def follow_robot(self, state: RobotState, command: JointCommand, now: float) -> None:
        """A cycle of a goal the robot runs itself: command nothing, estimate progress for feedback."""
        self.t = min(self.t + self._period * state.speed_scaling, self.duration)
        write_idle(command, state.positions, self._zeros)
        if now >= self.next_feedback:
            self.plan.sample(self.t, self._pos, self._vel, self._acc)
            self._feedback(self._pos, state.positions, now)

    def robot_ended(
        self, status: GoalStatus, reason: str, measured: Sequence[float]
    ) -> tuple[GoalStatus, str]:
        """The robot reports the goal it ran ended: the setpoint becomes the final point, and a reported
        success with a joint outside its goal tolerance an abort naming the joint."""
        self._pos[:] = self.final
        if status is GoalStatus.SUCCEEDED:
            for i, (final, actual) in enumerate(zip(self.final, measured, strict=True)):
                if abs(final - actual) > self.goal_tol[i]:
                    return GoalStatus.ABORTED, (
                        f"the robot reported success but {self._names[i]} is {final - actual:.4g} "
                        f"from its goal (tolerance {self.goal_tol[i]:.4g})"
                    )
        return status, reason

    def _feedback(self, desired: Sequence[float], actual: Sequence[float], now: float) -> None:
        self.next_feedback = now + self._feedback_period
        want, got = tuple(desired), tuple(actual)
        self._events.append(
            GoalFeedback(
                goal_id=self.goal_id,
                time_from_start=self.t,
                duration=self.duration,
                desired=want,
                actual=got,
                error=tuple(d - a for d, a in zip(want, got, strict=True)),
            )
        )

    def result(self, status: GoalStatus, reason: str, measured: Sequence[float]) -> GoalResult:
        """The goal's result, ending now with the robot at ``measured``."""
        actual = tuple(measured)
        return GoalResult(
            goal_id=self.goal_id,
            status=status,
            reason=reason,
            final_positions=actual,
            final_error=tuple(d - a for d, a in zip(self._pos, actual, strict=True)),
            duration=self.t,
        )
