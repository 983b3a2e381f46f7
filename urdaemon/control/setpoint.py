"""The setpoint: the joint state the controller commanded last cycle, kept across mode changes.

Owns the commanded position, velocity and acceleration (real time), the executing goal's sample in
trajectory time (velocity and acceleration before the speed scaling) with the goal's time scaling, and
the conversions between the two time bases that a change of mode needs: a goal continuing a stream or
a stop, a stop continuing a goal. Its lists are shared, never replaced: the goal run, the stream
follower, the stop ramp and the online generator keep references to them and write them in place.
Writing the cycle's command from the setpoint (or idle from the measured pose) is here too.
"""

from __future__ import annotations

from collections.abc import Sequence

from urdaemon.control.scaling import TimeScaling, clamp_scaling
from urdaemon.errors import GoalRejected
from urdaemon.model import CommandMode, JointCommand, JointLimits, RobotState

__all__ = ["MIN_SEED_SCALING", "Setpoint", "write_idle", "write_setpoint"]

MIN_SEED_SCALING = 0.05
"""Converting a real-time setpoint into trajectory time divides by the speed scaling; below this floor
the division would only produce huge values that ruckig then brakes anyway."""
_SLACK = 1.0 + 1e-9
_POSITION = CommandMode.POSITION
_IDLE = CommandMode.IDLE


def write_setpoint(command: JointCommand, pos: list[float], vel: list[float]) -> None:
    """Command position ``pos`` at velocity ``vel`` this cycle."""
    command.mode = _POSITION
    command.positions[:] = pos
    command.velocities[:] = vel


def write_idle(command: JointCommand, measured: Sequence[float], zeros: list[float]) -> None:
    """Command nothing this cycle (the measured pose, at rest)."""
    command.mode = _IDLE
    command.positions[:] = measured
    command.velocities[:] = zeros


class Setpoint:
    """The commanded joint state in real time, and the executing goal's in trajectory time."""

    __slots__ = ("_amax", "_names", "_vmax", "acc", "pacc", "pos", "pvel", "scaling", "vel", "zeros")

    def __init__(self, limits: JointLimits, planned: JointLimits, period: float) -> None:
        n = limits.dof
        self._names = limits.names
        self._vmax = list(limits.max_velocity)
        self._amax = list(limits.max_acceleration)
        self.pos = [0.0] * n
        """Commanded position (rad), the command of the last cycle."""
        self.vel = [0.0] * n
        self.acc = [0.0] * n
        self.pvel = [0.0] * n
        """The goal's sample in trajectory time: velocity before the speed scaling."""
        self.pacc = [0.0] * n
        self.scaling = TimeScaling(limits, planned, period)
        """The goal's time scaling: follows the robot's speed scaling within the joint limits."""
        self.zeros = [0.0] * n
        """All zero, never written: the velocity of an idle command, a rest target."""

    def rest_at(self, positions: Sequence[float]) -> None:
        """Start over at rest at ``positions`` (the measured pose: nothing was commanded)."""
        self.pos[:] = positions
        self.vel[:] = self.zeros
        self.acc[:] = self.zeros

    def at_rest(self) -> bool:
        """Whether the commanded velocity and acceleration are zero (a stop has come to rest)."""
        return not any(self.vel) and not any(self.acc)

    def goal_seed(
        self, state: RobotState, *, idle: bool, in_goal: bool
    ) -> tuple[list[float], list[float], list[float]]:
        """A new goal's start state in trajectory time: the measured pose at rest when ``idle``, the
        running goal's sample ``in_goal``, else this real-time state at the robot's speed scaling."""
        if in_goal:
            return self.goal_state()
        if idle:
            n = len(self.pos)
            return list(state.positions), [0.0] * n, [0.0] * n
        return self.in_trajectory_time(state.speed_scaling)

    def goal_start(self, state: RobotState, idle: bool, commanding: bool) -> tuple[list[float], bool]:
        """Where a new goal starts: the measured pose, at rest, when ``idle``; this setpoint while
        ``commanding`` (a goal or a stop), at rest if it is; the measured pose, moving, otherwise (a
        passthrough runs on the robot)."""
        if idle:
            return list(state.positions), True
        if commanding:
            return list(self.pos), self.at_rest()
        return list(state.positions), False

    def goal_state(self) -> tuple[list[float], list[float], list[float]]:
        """A copy of the running goal's state, in trajectory time: where a goal preempting it starts."""
        return list(self.pos), list(self.pvel), list(self.pacc)

    def in_trajectory_time(self, speed_scaling: float) -> tuple[list[float], list[float], list[float]]:
        """A copy of the real-time state (a stream's or a stop's) as a goal at ``speed_scaling`` sees it.

        Refused if the rescaled state is beyond the limits: a goal could not continue it without a jump.
        """
        s = max(speed_scaling, MIN_SEED_SCALING)
        vel = [v / s for v in self.vel]
        acc = [a / (s * s) for a in self.acc]
        for i, name in enumerate(self._names):
            if abs(vel[i]) > self._vmax[i] * _SLACK or abs(acc[i]) > self._amax[i] * _SLACK:
                raise GoalRejected(
                    f"cannot take over the current motion at speed scaling {speed_scaling:.3g}: "
                    f"{name} moves too fast to continue at that time scale; stop first"
                )
        return list(self.pos), vel, acc

    def start_goal(
        self,
        seed: tuple[list[float], list[float], list[float]],
        speed_scaling: float,
        *,
        at_rest: bool,
        after_goal: bool,
    ) -> None:
        """A goal starts from ``seed`` (trajectory time): at rest, after a goal it preempts, or else
        after a stream or a stop whose state ``in_trajectory_time`` converted at ``speed_scaling``."""
        seed_p, seed_v, seed_a = seed
        if at_rest:
            self.rest_at(seed_p)
        self.pvel[:] = seed_v
        self.pacc[:] = seed_a
        if at_rest:
            self.scaling.start(clamp_scaling(speed_scaling), seed_a)
        elif after_goal:
            self.scaling.start(None, seed_a)  # continues the pace of the goal it preempts: no jolt
        else:
            self.scaling.start(max(clamp_scaling(speed_scaling), MIN_SEED_SCALING), seed_a)

    def goal_to_real_time(self) -> None:
        """Make the goal's sample the real-time velocity and acceleration (a stop continues the goal)."""
        s = self.scaling.value
        r = self.scaling.rate
        vel = self.vel
        acc = self.acc
        pvel = self.pvel
        pacc = self.pacc
        for i in range(len(vel)):
            vel[i] = pvel[i] * s
            acc[i] = pacc[i] * s * s + pvel[i] * r
