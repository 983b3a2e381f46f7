"""Shared fixtures for the control tests: joint limits and a minimal simulated robot."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from urdaemon.control import GoalFeedback, GoalResult, MotionController
from urdaemon.model import UR_JOINTS, CommandMode, JointCommand, JointLimits, Lifecycle, RobotState

PERIOD = 0.002

UR10E_LIMITS = JointLimits(
    names=UR_JOINTS,
    min_position=(-2 * math.pi, -2 * math.pi, -math.pi, -2 * math.pi, -2 * math.pi, -2 * math.pi),
    max_position=(2 * math.pi, 2 * math.pi, math.pi, 2 * math.pi, 2 * math.pi, 2 * math.pi),
    max_velocity=(2.094, 2.094, 3.14159, 3.14159, 3.14159, 3.14159),
    max_acceleration=(5.0,) * 6,
    max_jerk=(50.0,) * 6,
)

THREE_LIMITS = JointLimits(
    names=("a", "b", "c"),
    min_position=(-1.0, -2.0, -0.5),
    max_position=(1.0, 2.0, 0.5),
    max_velocity=(2.0, 1.5, 1.0),
    max_acceleration=(5.0, 4.0, 3.0),
    max_jerk=(50.0, 40.0, 30.0),
)


def ready_state(names: tuple[str, ...], positions: list[float] | None = None) -> RobotState:
    """A RobotState that is ready for motion, at ``positions`` (default all zero)."""
    state = RobotState.zeros(names)
    state.lifecycle = Lifecycle.RUNNING
    state.program_running = True
    if positions is not None:
        state.positions[:] = positions
    return state


@dataclass
class SimRobot:
    """A robot that lands exactly on each commanded position one cycle later (while ``following``)."""

    controller: MotionController
    state: RobotState
    command: JointCommand
    period: float = PERIOD
    now: float = 0.0
    following: bool = True
    offset: list[float] | None = None
    commands: list[tuple[CommandMode, tuple[float, ...], tuple[float, ...]]] = field(default_factory=list)
    events: list[GoalFeedback | GoalResult] = field(default_factory=list)
    record: bool = True

    @classmethod
    def create(cls, limits: JointLimits, positions: list[float] | None = None, **kwargs: float) -> SimRobot:
        """A ready robot at ``positions`` with a fresh controller (kwargs go to MotionController)."""
        controller = MotionController(limits, period=PERIOD, **kwargs)
        return cls(controller, ready_state(limits.names, positions), JointCommand.idle(limits.dof))

    def step(self) -> None:
        """One cycle: tick the controller, let the robot follow, advance the clock."""
        self.controller.tick(self.state, self.command, self.now)
        if self.record:
            self.commands.append(
                (self.command.mode, tuple(self.command.positions), tuple(self.command.velocities))
            )
        if self.command.mode is CommandMode.POSITION and self.following:
            self.state.positions[:] = self.command.positions
            if self.offset is not None:
                for i, o in enumerate(self.offset):
                    self.state.positions[i] += o
            self.state.velocities[:] = self.command.velocities
        self.events.extend(self.controller.drain_events())
        self.now += self.period

    def run_until_result(self, goal_id: str, max_ticks: int) -> GoalResult:
        """Step until ``goal_id`` has a result (fails after ``max_ticks``)."""
        for _ in range(max_ticks):
            self.step()
            for event in self.events:
                if isinstance(event, GoalResult) and event.goal_id == goal_id:
                    return event
        raise AssertionError(f"no result for {goal_id} within {max_ticks} ticks")

    def run_until_idle(self, max_ticks: int) -> int:
        """Step until the controller is idle; returns the ticks taken (fails after ``max_ticks``)."""
        for k in range(max_ticks):
            self.step()
            if self.controller.mode == "idle":
                return k + 1
        raise AssertionError(f"not idle within {max_ticks} ticks (mode {self.controller.mode})")

    def results(self) -> list[GoalResult]:
        """The results seen so far, in order."""
        return [e for e in self.events if isinstance(e, GoalResult)]

    def feedback(self) -> list[GoalFeedback]:
        """The feedback seen so far, in order."""
        return [e for e in self.events if isinstance(e, GoalFeedback)]


def check_command_limits(
    commands: list[tuple[CommandMode, tuple[float, ...], tuple[float, ...]]],
    limits: JointLimits,
    period: float,
) -> tuple[float, float]:
    """Assert velocity and finite-difference acceleration limits over all commands; returns worst ratios.

    IDLE commands carry zero velocity, so leaving or entering IDLE is checked like any other cycle.
    """
    worst_v = 0.0
    worst_a = 0.0
    prev: tuple[float, ...] = (0.0,) * limits.dof
    for k, (_mode, _pos, vel) in enumerate(commands):
        for i, v in enumerate(vel):
            ratio_v = abs(v) / limits.max_velocity[i]
            worst_v = max(worst_v, ratio_v)
            assert ratio_v <= 1.0001, (
                f"cycle {k}: {limits.names[i]} velocity {v} over {limits.max_velocity[i]}"
            )
            acc = (v - prev[i]) / period
            ratio_a = abs(acc) / limits.max_acceleration[i]
            worst_a = max(worst_a, ratio_a)
            assert ratio_a <= 1.05, f"cycle {k}: {limits.names[i]} acceleration {acc} over the limit"
        prev = vel
    return worst_v, worst_a
