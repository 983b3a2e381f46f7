"""The stop: a jerk-limited ramp of the setpoint to rest, and the hold of a succeeded goal's point.

Owns the ramp's progress and the hold. Every stop (a cancel, a stop request, the deadman, a goal
ending) brings the setpoint to rest from wherever it is, through the online generator. After a goal
succeeded, the stop goes on holding the goal's final point until the robot rests on it (within
``SETTLE_POSITION`` and ``SETTLE_VELOCITY``) or ``SETTLE_TIME`` has passed: a robot follows its
setpoint with a lag, so letting go as soon as the goal tolerance is met would leave it wherever the
lag had it. Only after success: a robot that cannot reach a point must not be pushed toward it.
"""

from __future__ import annotations

from urdaemon.control.online import FINISHED, OnlineGenerator
from urdaemon.control.setpoint import Setpoint, write_setpoint
from urdaemon.model import JointCommand, RobotState

__all__ = ["SETTLE_POSITION", "SETTLE_TIME", "SETTLE_VELOCITY", "StopRamp"]

SETTLE_POSITION = 2e-5
"""rad: how close every joint must be to a succeeded goal's final point for the hold to end."""
SETTLE_VELOCITY = 1e-3
"""rad/s: how slowly every joint must move for the hold to end."""
SETTLE_TIME = 1.0
"""s: how long the final point of a succeeded goal is held at most for the robot to settle on it. A
robot follows its setpoint with a lag (a UR's servoj: lookahead time × speed), so letting go when the
goal tolerance is met would leave it wherever the lag had it (the tolerance, not the target); UR's ROS 2
driver holds the last point for the same reason. Only after success: a stop, cancel or deadman lets go
once its ramp has ended, as a robot that cannot reach a point must not be pushed toward it."""


class StopRamp:
    """Ramps the setpoint to rest; after a succeeded goal, holds it until the robot settles there."""

    __slots__ = (
        "_hold",
        "_online",
        "_pos",
        "_ramp_done",
        "_setpoint",
        "_settle_limit",
        "_settle_ticks",
        "_vel",
        "_zeros",
    )

    def __init__(self, period: float, online: OnlineGenerator, setpoint: Setpoint) -> None:
        self._online = online
        self._setpoint = setpoint
        self._pos = setpoint.pos
        self._vel = setpoint.vel
        self._zeros = setpoint.zeros
        self._hold = False
        """The stop holds a succeeded goal's final point until the robot settles on it."""
        self._ramp_done = False
        """The ramp has ended (only a hold keeps the stop going)."""
        self._settle_ticks = 0
        self._settle_limit = max(1, round(SETTLE_TIME / period))

    @property
    def only_holding(self) -> bool:
        """Whether the ramp has ended and all that goes on is the hold of a succeeded goal's point."""
        return self._hold and self._ramp_done

    def start(self, *, hold: bool, after_goal: bool) -> None:
        """Ramp to rest from the setpoint (a goal's made real-time first, ``after_goal``); ``hold``: then
        hold the point it rests at until the robot settles there."""
        if after_goal:
            self._setpoint.goal_to_real_time()
        self._online.seed()
        self._online.toward_velocity(self._zeros)
        self._hold = hold
        self._ramp_done = False
        self._settle_ticks = 0

    def tick(self, state: RobotState, command: JointCommand) -> bool:
        """One cycle of the stop; True when it wrote this cycle's setpoint, False when it is over."""
        result = self._online.step()
        if result == FINISHED:
            self._ramp_done = True
        if result is None or (result == FINISHED and (not self._hold or self._settled(state))):
            return False
        write_setpoint(command, self._pos, self._vel)
        return True

    def _settled(self, state: RobotState) -> bool:
        """Whether the robot rests on the held point, or has been given all the time it gets."""
        self._settle_ticks += 1
        if self._settle_ticks > self._settle_limit:
            return True
        pos = self._pos
        meas = state.positions
        speed = state.velocities
        for i in range(len(pos)):
            if abs(pos[i] - meas[i]) > SETTLE_POSITION or abs(speed[i]) > SETTLE_VELOCITY:
                return False
        return True
