"""MotionController.accept_planned and goal_start: a plan made before it starts (a linear goal's).

A ready plan is made for the pose the robot rests at (``goal_start``), in slices while the robot
waits; ``accept_planned`` then starts it, or refuses it when the robot is busy or no longer there.
Plans here are control/move.py's ``plan_move`` results: they have the shape every ready plan
has (duration, final_positions, final_velocities, segment_count, sample, release).
"""

from __future__ import annotations

from collections.abc import Sequence

import pytest

from urdaemon.control import GoalStatus, TrajectoryPoint
from urdaemon.control.move import plan_move
from urdaemon.control.planned import PLAN_START_TOLERANCE
from urdaemon.control.planned_trajectory import PlannedTrajectory
from urdaemon.control.stopping import SETTLE_POSITION
from urdaemon.errors import GoalRejected
from urdaemon.model import UR_JOINTS

from .sim import PERIOD, UR10E_LIMITS, SimRobot, check_command_limits

NAMES = UR_JOINTS


def _plan_from(robot: SimRobot, target: Sequence[float]) -> PlannedTrajectory:
    """A plan from where a new goal of ``robot`` starts, at rest, to ``target``."""
    joints, at_rest = robot.controller.goal_start(robot.state)
    assert at_rest
    n = len(joints)
    return plan_move(joints, [0.0] * n, [0.0] * n, target, robot.controller.plan_limits)


def test_a_plan_made_at_rest_runs_to_success_from_the_measured_pose() -> None:
    """accept_planned did not exist before issue 17 (AttributeError on the old controller)."""
    start = [0.1, -0.5, 0.4, 0.0, 0.3, 0.0]
    robot = SimRobot.create(UR10E_LIMITS, start)
    joints, at_rest = robot.controller.goal_start(robot.state)
    assert (joints, at_rest) == (start, True)
    target = [0.4, -0.7, 0.8, 0.2, 0.1, -0.3]
    plan = _plan_from(robot, target)
    duration = robot.controller.accept_planned("p1", plan, robot.state, robot.now)
    assert duration == plan.duration
    assert robot.controller.mode == "goal"
    assert robot.controller.active_goal_id == "p1"
    # While the goal runs, a new goal would start from the setpoint, not at rest.
    robot.step()
    joints, at_rest = robot.controller.goal_start(robot.state)
    assert not at_rest
    assert joints == list(robot.commands[-1][1])
    result = robot.run_until_result("p1", round(duration / PERIOD) + 100)
    assert result.status is GoalStatus.SUCCEEDED
    assert robot.state.positions == pytest.approx(target, abs=1e-9)
    check_command_limits(robot.commands, UR10E_LIMITS, PERIOD)


def test_a_robot_that_moved_since_the_plan_was_made_is_refused_naming_the_joint() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    plan = _plan_from(robot, [0.3, 0.0, 0.0, 0.0, 0.0, 0.0])
    robot.state.positions[3] += 2.0 * PLAN_START_TOLERANCE
    with pytest.raises(GoalRejected, match=r"not at the plan's start: wrist_1_joint moved 4e-05 rad since"):
        robot.controller.accept_planned("p1", plan, robot.state, robot.now)
    assert robot.controller.mode == "idle"
    # Within the tolerance it starts, at the plan's start: the first command continues the plan.
    robot.state.positions[3] -= 1.5 * PLAN_START_TOLERANCE
    robot.controller.accept_planned("p1", plan, robot.state, robot.now)
    robot.step()
    assert robot.commands[-1][1][3] == pytest.approx(0.0, abs=1e-9)


def test_a_plan_that_does_not_start_at_rest_is_refused() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    n = len(NAMES)
    moving = plan_move([0.0] * n, [0.0, 0.2, 0, 0, 0, 0], [0.0] * n, [0.5] * n, robot.controller.plan_limits)
    with pytest.raises(GoalRejected, match=r"does not start at rest: shoulder_lift_joint starts at 0\.2"):
        robot.controller.accept_planned("p1", moving, robot.state, robot.now)


def test_busy_robots_refuse_a_plan_as_a_move_is_refused() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    plan = _plan_from(robot, [0.3, 0.0, 0.0, 0.0, 0.0, 0.0])
    robot.controller.accept_move("m1", NAMES, [0.0, 0.5, 0.0, 0.0, 0.0, 0.0], robot.state, robot.now)
    robot.step()
    with pytest.raises(GoalRejected, match="busy: goal m1 is executing"):
        robot.controller.accept_planned("p1", plan, robot.state, robot.now)
    robot.controller.cancel()
    # A stop still ramping down: the robot moves, and a plan starts from rest.
    robot.step()
    assert robot.controller.mode == "stopping"
    with pytest.raises(GoalRejected, match="busy: the robot is stopping; a planned goal starts from rest"):
        robot.controller.accept_planned("p1", plan, robot.state, robot.now)
    robot.run_until_idle(2000)
    # An active joint stream.
    robot.controller.stream_velocities(NAMES, [0.1, 0, 0, 0, 0, 0], robot.state, robot.now)
    robot.step()
    with pytest.raises(GoalRejected, match="busy: a joint stream is active"):
        robot.controller.accept_planned("p1", plan, robot.state, robot.now)
    # A stream whose deadman has run out but is still braking: moving.
    robot.now += 1.0
    robot.step()
    assert robot.controller.mode == "stopping"
    with pytest.raises(GoalRejected, match="a planned goal starts from rest"):
        robot.controller.accept_planned("p1", plan, robot.state, robot.now)
    # A robot not ready.
    robot.run_until_idle(2000)
    robot.state.program_running = False
    with pytest.raises(GoalRejected, match="robot not ready"):
        robot.controller.accept_planned("p1", plan, robot.state, robot.now)


def test_a_plan_made_while_a_succeeded_goal_is_held_starts_from_the_held_point() -> None:
    """After a goal succeeds, the controller holds its final point (stopping, at rest) until the robot
    settles: a plan made then starts from that point and takes over the hold without a jump."""
    robot = SimRobot.create(UR10E_LIMITS)
    first = [0.2, -0.1, 0.3, 0.0, 0.0, 0.0]
    robot.controller.accept_trajectory("g1", NAMES, [TrajectoryPoint(tuple(first), 1.0)], robot.state, 0.0)
    # The robot lags a little behind its setpoint (more than it settles within), so the hold goes on;
    # a plan made now starts from the held point, where the setpoint stays: no jump.
    robot.offset = [-5e-4, 0.0, 0.0, 0.0, 0.0, 0.0]
    robot.run_until_result("g1", 1000)
    robot.step()
    assert robot.controller.mode == "stopping"
    joints, at_rest = robot.controller.goal_start(robot.state)
    assert at_rest
    assert joints == pytest.approx(first, abs=1e-12)
    plan = _plan_from(robot, [0.0] * 6)
    robot.controller.accept_planned("p2", plan, robot.state, robot.now)
    assert robot.controller.mode == "goal"
    robot.step()
    assert robot.commands[-1][1] == pytest.approx(first, abs=1e-6)
    assert robot.run_until_result("p2", 2000).status is GoalStatus.SUCCEEDED
    check_command_limits(robot.commands, UR10E_LIMITS, PERIOD)


def test_the_start_tolerance_is_a_resting_arms_noise() -> None:
    """One fact: a plan's start may differ from where the robot rests by what the stop counts as
    settled, no more (it was 1e-3 rad: 50 times that, a visible step in one cycle)."""
    assert PLAN_START_TOLERANCE == SETTLE_POSITION == 2e-5


def test_a_robot_jogged_while_its_plan_was_made_is_refused_and_never_steps() -> None:
    """Review of issue 17: a linear goal is planned at rest, in slices; meanwhile a stream (or force
    mode, or a push) moves a joint 0.6 mrad and the robot comes to rest again. Accepted, the plan's
    first cycle stepped back to its stale start (30 times the acceleration limit from rest)."""
    robot = SimRobot.create(UR10E_LIMITS, [0.1, -0.5, 0.4, 0.0, 0.3, 0.0], stream_timeout=0.05)
    plan = _plan_from(robot, [0.4, -0.7, 0.8, 0.2, 0.1, -0.3])
    robot.controller.stream_velocities(NAMES, [0, 0, 0, 0.012, 0, 0], robot.state, robot.now)
    for _ in range(8):
        robot.step()
    robot.run_until_idle(2000)  # the deadman stopped it: at rest again, a fraction of a mrad away
    moved = robot.state.positions[3]
    assert 2e-4 < moved < 1e-3
    with pytest.raises(GoalRejected, match=r"not at the plan's start: wrist_1_joint moved 0\.0006 rad since"):
        robot.controller.accept_planned("p1", plan, robot.state, robot.now)
    assert robot.controller.mode == "idle"
    robot.step()
    assert robot.state.positions[3] == moved
    # Planned again from where it rests, it starts there: the first cycle does not step.
    again = _plan_from(robot, [0.4, -0.7, 0.8, 0.2, 0.1, -0.3])
    robot.controller.accept_planned("p2", again, robot.state, robot.now)
    robot.step()
    assert abs(robot.commands[-1][1][3] - moved) <= 0.01 * UR10E_LIMITS.max_velocity[3] * PERIOD
