"""The speed scaling changes a goal's pace without breaking the joint limits (issue 13, finding 8).

Every check here works on the commanded positions alone: velocity, acceleration and jerk are their
first, second and third finite differences per cycle, as the robot's drives would see them.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from urdaemon.control import GoalStatus, TrajectoryPoint
from urdaemon.errors import GoalRejected
from urdaemon.model import UR_JOINTS, CommandMode, JointLimits

from .sim import PERIOD, THREE_LIMITS, UR10E_LIMITS, SimRobot

TOLERANCE = 1e-6
"""Relative slack for float round-off in the finite differences (stops run at the limits exactly)."""

UR_POINTS = [
    TrajectoryPoint((0.5, -0.5, 1.0, 0.2, -0.3, 1.5), 2.0),
    TrajectoryPoint((1.0, -1.0, 2.0, 0.4, -0.6, 3.0), 4.0),
    TrajectoryPoint((0.2, -0.2, 0.4, 0.1, 0.0, 0.5), 7.0),
]
FAR = (3.0, -2.0, 2.5, 1.0, -3.0, 3.0)
"""A time-optimal move there runs at the velocity, acceleration and jerk limits most of the way."""


def worst_ratios(robot: SimRobot, limits: JointLimits) -> tuple[float, float, float, int]:
    """Largest |v|/vmax, |a|/amax, |j|/jmax over all cycles and joints, and the cycle of the worst jerk."""
    positions = [pos for _mode, pos, _vel in robot.commands]
    dt = PERIOD
    worst_v = worst_a = worst_j = 0.0
    at = -1
    for k in range(3, len(positions)):
        p0, p1, p2, p3 = positions[k], positions[k - 1], positions[k - 2], positions[k - 3]
        for i in range(limits.dof):
            v = (p0[i] - p1[i]) / dt
            a = (p0[i] - 2.0 * p1[i] + p2[i]) / dt**2
            j = (p0[i] - 3.0 * p1[i] + 3.0 * p2[i] - p3[i]) / dt**3
            worst_v = max(worst_v, abs(v) / limits.max_velocity[i])
            worst_a = max(worst_a, abs(a) / limits.max_acceleration[i])
            if abs(j) / limits.max_jerk[i] > worst_j:
                worst_j = abs(j) / limits.max_jerk[i]
                at = k
    return worst_v, worst_a, worst_j, at


def assert_within_limits(robot: SimRobot, limits: JointLimits) -> None:
    worst_v, worst_a, worst_j, at = worst_ratios(robot, limits)
    assert worst_j <= 1.0 + TOLERANCE, f"jerk at {worst_j:.4g} of its limit (cycle {at})"
    assert worst_a <= 1.0 + TOLERANCE, f"acceleration at {worst_a:.4g} of its limit"
    assert worst_v <= 1.0 + TOLERANCE, f"velocity at {worst_v:.4g} of its limit"


def run_goal(robot: SimRobot, goal_id: str, steps: dict[int, float], max_ticks: int = 40_000) -> GoalStatus:
    """Step until the goal's result, setting the robot's speed scaling at the given cycles."""
    for k in range(max_ticks):
        if k in steps:
            robot.state.speed_scaling = steps[k]
        robot.step()
        for result in robot.results():
            if result.goal_id == goal_id:
                for _ in range(3):  # the stop after a goal, and idle
                    robot.step()
                return result.status
    raise AssertionError(f"no result within {max_ticks} cycles")


def test_stepping_the_speed_scaling_mid_goal_keeps_every_cycle_within_the_jerk_limit() -> None:
    """Reproduction: speed scaling 1.0 -> 0.3 in one step mid-goal commanded a one-cycle jerk of
    4.8e5 rad/s³ (limit 50): trajectory time advanced at the robot's scaling, applied as a step.
    Here 1.0 -> 0.3 at cycle 500 and back to 1.0 at cycle 1500, with the robot's trajectory."""
    robot = SimRobot.create(UR10E_LIMITS)
    robot.controller.accept_trajectory("g", UR_JOINTS, UR_POINTS, robot.state, robot.now)
    assert run_goal(robot, "g", {500: 0.3, 1500: 1.0}) is GoalStatus.SUCCEEDED
    assert_within_limits(robot, UR10E_LIMITS)
    (result,) = robot.results()
    assert result.final_positions == pytest.approx(UR_POINTS[-1].positions, abs=1e-9)
    assert robot.commands[-1][0] is CommandMode.IDLE
    # It did slow down: the goal took longer than at full speed (3500 cycles).
    assert len(robot.commands) > 4000


def test_a_step_to_zero_brings_the_goal_to_rest_smoothly_and_it_resumes() -> None:
    """Reproduction: the slider to 0 mid-goal stopped the commanded motion in one cycle."""
    robot = SimRobot.create(UR10E_LIMITS)
    robot.controller.accept_move("m", UR_JOINTS, FAR, robot.state, robot.now)
    robot.state.speed_scaling = 1.0
    for _ in range(400):
        robot.step()
    robot.state.speed_scaling = 0.0
    for _ in range(3000):
        robot.step()
        if robot.commands[-1][2] == (0.0,) * 6:
            break
    held = robot.commands[-1][1]
    for _ in range(50):
        robot.step()
    assert robot.commands[-1][1] == held, "trajectory time stands still at speed scaling 0"
    assert robot.results() == []
    assert run_goal(robot, "m", {0: 1.0}) is GoalStatus.SUCCEEDED
    assert_within_limits(robot, UR10E_LIMITS)
    assert robot.results()[0].final_positions == pytest.approx(FAR, abs=1e-9)


@settings(max_examples=25, deadline=None)
@given(
    move=st.booleans(),
    first=st.integers(min_value=0, max_value=1200),
    gap=st.integers(min_value=1, max_value=1200),
    low=st.sampled_from([0.0, 0.3]) | st.floats(min_value=0.0, max_value=1.0),
    high=st.floats(min_value=0.3, max_value=1.0),
)
def test_random_scaling_steps_keep_the_limits(
    move: bool, first: int, gap: int, low: float, high: float
) -> None:
    """Steps at random cycles and to random values, on a time-optimal move (at the limits most of the
    way) and on a slow trajectory: every cycle within the limits, the goal ends where asked."""
    robot = SimRobot.create(UR10E_LIMITS)
    target: tuple[float, ...]
    if move:
        robot.controller.accept_move("g", UR_JOINTS, FAR, robot.state, robot.now)
        target = FAR
    else:
        robot.controller.accept_trajectory("g", UR_JOINTS, UR_POINTS, robot.state, robot.now)
        target = UR_POINTS[-1].positions
    assert run_goal(robot, "g", {first: low, first + gap: high}) is GoalStatus.SUCCEEDED
    assert_within_limits(robot, UR10E_LIMITS)
    assert robot.results()[0].final_positions == pytest.approx(target, abs=1e-9)


def test_a_preempt_and_a_cancel_during_the_ramp_keep_the_limits() -> None:
    """A new goal while the scaling ramps continues its pace; a cancel's stop starts from the real
    acceleration (including p'·s', the ramp's own share)."""
    robot = SimRobot.create(THREE_LIMITS)
    names = THREE_LIMITS.names
    robot.controller.accept_move("a", names, [0.9, 1.8, 0.4], robot.state, robot.now)
    for _ in range(300):
        robot.step()
    robot.state.speed_scaling = 0.2
    for _ in range(100):
        robot.step()
    robot.controller.accept_move("b", names, [-0.9, -1.5, -0.4], robot.state, robot.now, preempt=True)
    robot.state.speed_scaling = 1.0
    for _ in range(300):
        robot.step()
    robot.state.speed_scaling = 0.5
    for _ in range(50):
        robot.step()
    assert robot.controller.cancel("b")
    robot.run_until_idle(5000)
    statuses = [r.status for r in robot.results()]
    assert statuses == [GoalStatus.PREEMPTED, GoalStatus.CANCELED]
    assert_within_limits(robot, THREE_LIMITS)


def test_goals_keep_a_reserve_of_acceleration_and_jerk_for_the_scaling() -> None:
    """Goals are planned within 95 % of max_acceleration and 90 % of max_jerk; a client point asking
    for an acceleration inside the reserve is refused, saying why."""
    robot = SimRobot.create(THREE_LIMITS)
    planned = robot.controller.plan_limits
    assert planned.max_acceleration == pytest.approx([0.95 * a for a in THREE_LIMITS.max_acceleration])
    assert planned.max_jerk == pytest.approx([0.9 * j for j in THREE_LIMITS.max_jerk])
    points = [
        TrajectoryPoint((0.5, 0.0, 0.0), 2.0, velocities=(0.1, 0.0, 0.0), accelerations=(4.9, 0.0, 0.0)),
        TrajectoryPoint((0.6, 0.0, 0.0), 4.0),
    ]
    with pytest.raises(
        GoalRejected, match=r"point 0: a acceleration 4\.9 exceeds 4\.75, 95 % of its limit 5"
    ):
        robot.controller.accept_trajectory("t", THREE_LIMITS.names, points, robot.state, robot.now)
