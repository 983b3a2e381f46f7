"""MotionController streams: position and velocity streaming, deadman stop, limit guards, busy rules."""

from __future__ import annotations

import math

import pytest

from urdaemon.control import GoalStatus, TrajectoryPoint
from urdaemon.errors import GoalRejected
from urdaemon.model import UR_JOINTS, CommandMode

from .sim import PERIOD, THREE_LIMITS, UR10E_LIMITS, SimRobot, check_command_limits

NAMES3 = ("a", "b", "c")


def test_position_stream_reaches_target_then_deadman_goes_idle() -> None:
    robot = SimRobot.create(THREE_LIMITS, stream_timeout=0.2)
    target = [0.5, -0.4, 0.2]
    for _ in range(600):
        robot.controller.stream_positions(NAMES3, target, None, robot.state, robot.now)
        robot.step()
    assert robot.controller.mode == "stream_position"
    assert robot.state.positions == pytest.approx(target, abs=1e-9)
    last_command = robot.now - PERIOD
    robot.run_until_idle(200)
    # Idle on the first cycle more than stream_timeout after the last command (already at rest).
    idle_at = robot.now - PERIOD
    assert 0.2 < idle_at - last_command <= 0.2 + PERIOD + 1e-9
    stats = robot.controller.statistics()
    assert stats.deadman_stops == 1
    assert stats.stream_commands == 600
    assert robot.commands[-1][0] is CommandMode.IDLE
    check_command_limits(robot.commands, THREE_LIMITS, PERIOD)


def test_position_stream_in_client_order_with_velocities_tracks_a_moving_target() -> None:
    robot = SimRobot.create(THREE_LIMITS)
    # Client order c, a, b; a sine on joint a and b, c fixed.
    worst = 0.0
    for k in range(1500):
        t = k * PERIOD
        a, va = 0.4 * math.sin(2.0 * t), 0.8 * math.cos(2.0 * t)
        b, vb = 0.3 * (1.0 - math.cos(1.5 * t)), 0.45 * math.sin(1.5 * t)
        robot.controller.stream_positions(("c", "a", "b"), [0.1, a, b], [0.0, va, vb], robot.state, robot.now)
        robot.step()
        if k > 500:
            pos = robot.commands[-1][1]
            worst = max(worst, abs(pos[0] - a), abs(pos[1] - b), abs(pos[2] - 0.1))
    # Time-optimal online tracking of a target that keeps moving lags a little (no time synchronization,
    # the target acceleration is unknown): a few hundredths of a radian at these speeds.
    assert worst < 0.06
    assert robot.commands[-1][2][0] == pytest.approx(0.8 * math.cos(2.0 * 1499 * PERIOD), abs=0.1)
    # Stop streaming while moving: a ramp to rest, not a jump.
    ticks = robot.run_until_idle(1000)
    assert ticks > 0.2 / PERIOD + 5
    check_command_limits(robot.commands, THREE_LIMITS, PERIOD)
    assert robot.controller.statistics().deadman_stops == 1


def test_velocity_stream_reaches_velocity_then_deadman_ramps_down() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    target = [0.5, -0.3, 0.0, 0.2, 0.0, -1.0]
    for _ in range(300):
        robot.controller.stream_velocities(UR_JOINTS, target, robot.state, robot.now)
        robot.step()
    assert robot.controller.mode == "stream_velocity"
    assert robot.commands[-1][2] == pytest.approx(target, abs=1e-9)
    # Positions integrate the velocity.
    assert robot.commands[-1][1][5] < -0.4
    ticks = robot.run_until_idle(1000)
    assert ticks > 0.2 / PERIOD + 10
    assert robot.controller.statistics().deadman_stops == 1
    check_command_limits(robot.commands, UR10E_LIMITS, PERIOD)


def test_velocity_stream_stops_before_a_limit_and_does_not_creep() -> None:
    robot = SimRobot.create(THREE_LIMITS)
    limit = THREE_LIMITS.max_position[2]
    highest = -math.inf
    for _ in range(1000):
        robot.controller.stream_velocities(NAMES3, [0.0, 0.0, 1.0], robot.state, robot.now)
        robot.step()
        highest = max(highest, robot.commands[-1][1][2])
    assert highest <= limit
    assert highest > limit - 0.2  # it did get close
    parked = robot.commands[-1][1][2]
    assert robot.commands[-1][2][2] == 0.0
    for _ in range(300):
        robot.controller.stream_velocities(NAMES3, [0.0, 0.0, 1.0], robot.state, robot.now)
        robot.step()
    assert robot.commands[-1][1][2] == parked
    # Reversing is allowed.
    for _ in range(300):
        robot.controller.stream_velocities(NAMES3, [0.0, 0.0, -0.5], robot.state, robot.now)
        robot.step()
    assert robot.commands[-1][1][2] < parked - 0.1
    check_command_limits(robot.commands, THREE_LIMITS, PERIOD)


def test_velocity_stream_guards_the_lower_limit_too() -> None:
    robot = SimRobot.create(THREE_LIMITS)
    lowest = math.inf
    for _ in range(2000):
        robot.controller.stream_velocities(NAMES3, [-2.0, -1.5, 0.0], robot.state, robot.now)
        robot.step()
        lowest = min(lowest, robot.commands[-1][1][0])
        assert robot.commands[-1][1][1] >= THREE_LIMITS.min_position[1]
    assert THREE_LIMITS.min_position[0] <= lowest < THREE_LIMITS.min_position[0] + 0.2


def test_position_stream_does_not_overshoot_a_limit_when_the_target_jumps_close_to_it() -> None:
    robot = SimRobot.create(THREE_LIMITS, positions=[-0.9, 0.0, 0.0])
    # Race toward +1 ...
    for _ in range(400):
        robot.controller.stream_positions(NAMES3, [1.0, 0.0, 0.0], None, robot.state, robot.now)
        robot.step()
    assert robot.commands[-1][2][0] > 1.5
    # ... it would brake in time for the target, but a target just below the limit after passing is not.
    highest = -math.inf
    for _ in range(600):
        robot.controller.stream_positions(NAMES3, [0.2, 0.0, 0.0], None, robot.state, robot.now)
        robot.step()
        highest = max(highest, robot.commands[-1][1][0])
    assert highest <= THREE_LIMITS.max_position[0]
    check_command_limits(robot.commands, THREE_LIMITS, PERIOD)


def test_position_stream_coasting_at_target_velocity_stops_before_the_limit() -> None:
    robot = SimRobot.create(THREE_LIMITS, stream_timeout=10.0)
    # The target carries a velocity toward the limit, then the client falls silent (before the deadman).
    for _ in range(300):
        robot.controller.stream_positions(NAMES3, [0.3, 0.0, 0.0], [1.0, 0.0, 0.0], robot.state, robot.now)
        robot.step()
    highest = -math.inf
    for _ in range(1500):
        robot.step()
        highest = max(highest, robot.commands[-1][1][0])
    assert highest <= THREE_LIMITS.max_position[0]
    assert highest > 0.8
    assert robot.commands[-1][2][0] == 0.0
    check_command_limits(robot.commands, THREE_LIMITS, PERIOD)


def test_position_stream_target_velocity_that_cannot_stop_in_time_is_dropped() -> None:
    robot = SimRobot.create(THREE_LIMITS, stream_timeout=10.0)
    highest = -math.inf
    for _ in range(1000):
        robot.controller.stream_positions(NAMES3, [0.99, 0.0, 0.0], [2.0, 0.0, 0.0], robot.state, robot.now)
        robot.step()
        highest = max(highest, robot.commands[-1][1][0])
    assert highest <= THREE_LIMITS.max_position[0]
    assert robot.commands[-1][1][0] == pytest.approx(0.99, abs=1e-9)


def test_stream_is_rejected_while_a_goal_executes() -> None:
    robot = SimRobot.create(THREE_LIMITS)
    robot.controller.accept_move("g1", NAMES3, [0.5, 0.0, 0.0], robot.state, robot.now)
    with pytest.raises(GoalRejected) as info:
        robot.controller.stream_positions(NAMES3, [0.0, 0.0, 0.0], None, robot.state, robot.now)
    assert info.value.reason == "busy: goal g1 is executing"
    with pytest.raises(GoalRejected, match="busy: goal g1 is executing"):
        robot.controller.stream_velocities(NAMES3, [0.0, 0.0, 0.0], robot.state, robot.now)


def test_goal_is_rejected_while_a_stream_is_active_unless_preempting() -> None:
    robot = SimRobot.create(THREE_LIMITS)
    for _ in range(100):
        robot.controller.stream_velocities(NAMES3, [0.5, 0.0, 0.0], robot.state, robot.now)
        robot.step()
    with pytest.raises(GoalRejected) as info:
        robot.controller.accept_move("g1", NAMES3, [0.0, 0.0, 0.0], robot.state, robot.now)
    assert info.value.reason.startswith("busy: a joint stream is active")
    robot.controller.accept_move("g1", NAMES3, [0.0, 0.0, 0.0], robot.state, robot.now, preempt=True)
    result = robot.run_until_result("g1", 2000)
    assert result.status is GoalStatus.SUCCEEDED
    # The goal took over from the moving stream setpoint without a jump.
    check_command_limits(robot.commands, THREE_LIMITS, PERIOD)


def test_goal_after_the_stream_timed_out_continues_from_the_setpoint() -> None:
    robot = SimRobot.create(THREE_LIMITS)
    for _ in range(100):
        robot.controller.stream_velocities(NAMES3, [1.0, 0.0, 0.0], robot.state, robot.now)
        robot.step()
    for _ in range(110):  # the deadman fires and the stop is under way
        robot.step()
    assert robot.controller.mode == "stopping"
    robot.controller.accept_trajectory(
        "g1", NAMES3, [TrajectoryPoint((0.0, 0.0, 0.0), 2.0)], robot.state, robot.now
    )
    assert robot.run_until_result("g1", 2000).status is GoalStatus.SUCCEEDED
    check_command_limits(robot.commands, THREE_LIMITS, PERIOD)


def test_stop_ends_a_stream_smoothly_and_frees_the_robot() -> None:
    robot = SimRobot.create(THREE_LIMITS)
    for _ in range(200):
        robot.controller.stream_velocities(NAMES3, [0.0, 1.0, 0.0], robot.state, robot.now)
        robot.step()
    robot.controller.stop("client disconnected", robot.now)
    assert robot.controller.mode == "stopping"
    # No longer busy: a goal is accepted without preempt.
    robot.controller.accept_move("g1", NAMES3, [0.0, 0.5, 0.0], robot.state, robot.now)
    assert robot.run_until_result("g1", 2000).status is GoalStatus.SUCCEEDED
    assert robot.controller.statistics().deadman_stops == 0
    check_command_limits(robot.commands, THREE_LIMITS, PERIOD)


def test_switching_stream_kinds_is_continuous() -> None:
    robot = SimRobot.create(THREE_LIMITS)
    for _ in range(150):
        robot.controller.stream_velocities(NAMES3, [1.0, -1.0, 0.5], robot.state, robot.now)
        robot.step()
    for _ in range(600):
        robot.controller.stream_positions(NAMES3, [0.0, 0.0, 0.0], None, robot.state, robot.now)
        robot.step()
    for _ in range(150):
        robot.controller.stream_velocities(NAMES3, [-1.0, 1.0, 0.0], robot.state, robot.now)
        robot.step()
    robot.run_until_idle(1000)
    check_command_limits(robot.commands, THREE_LIMITS, PERIOD)


def test_stream_from_idle_seeds_from_the_measured_pose() -> None:
    robot = SimRobot.create(THREE_LIMITS)
    for _ in range(200):
        robot.controller.stream_positions(NAMES3, [0.5, 0.5, 0.2], None, robot.state, robot.now)
        robot.step()
    robot.state.program_running = False
    robot.step()
    assert robot.controller.mode == "idle"
    moved = [-0.3, 0.1, 0.0]
    robot.state.positions[:] = moved
    robot.state.program_running = True
    robot.controller.stream_positions(NAMES3, [-0.3, 0.1, 0.05], None, robot.state, robot.now)
    robot.step()
    first = robot.commands[-1][1]
    assert max(abs(a - b) for a, b in zip(first, moved, strict=True)) < 1e-4


@pytest.mark.parametrize(
    ("names", "positions", "velocities", "expected"),
    [
        (("a", "b", "z"), [0.0, 0.0, 0.0], None, "unknown joint(s) 'z'"),
        (("a", "b"), [0.0, 0.0], None, "missing joint(s) 'c'"),
        (("a", "a", "c"), [0.0, 0.0, 0.0], None, "joint 'a' is listed twice"),
        (NAMES3, [0.0, 0.0], None, "positions has 2 values for 3 joints"),
        (NAMES3, [0.0, math.nan, 0.0], None, "positions: b is nan"),
        (NAMES3, [0.0, 0.0, -0.7], None, "stream target: c position -0.7 is outside its limits [-0.5, 0.5]"),
        (NAMES3, [0.0, 0.0, 0.0], [0.0, 0.0, 1.5], "stream target: c velocity 1.5 exceeds its limit 1"),
        (NAMES3, [0.0, 0.0, 0.0], [0.0, math.inf, 0.0], "velocities: b is inf"),
        (NAMES3, [0.0, 0.0, 0.0], [0.0, 0.0], "velocities has 2 values for 3 joints"),
    ],
)
def test_position_stream_rejections(
    names: tuple[str, ...], positions: list[float], velocities: list[float] | None, expected: str
) -> None:
    robot = SimRobot.create(THREE_LIMITS)
    with pytest.raises(GoalRejected) as info:
        robot.controller.stream_positions(names, positions, velocities, robot.state, robot.now)
    assert expected in info.value.reason
    assert robot.controller.mode == "idle"
    assert robot.controller.statistics().stream_commands == 0


@pytest.mark.parametrize(
    ("velocities", "expected"),
    [
        ([0.0, -1.6, 0.0], "stream target: b velocity -1.6 exceeds its limit 1.5"),
        ([math.nan, 0.0, 0.0], "velocities: a is nan"),
        ([0.0, 0.0], "velocities has 2 values for 3 joints"),
    ],
)
def test_velocity_stream_rejections(velocities: list[float], expected: str) -> None:
    robot = SimRobot.create(THREE_LIMITS)
    with pytest.raises(GoalRejected) as info:
        robot.controller.stream_velocities(NAMES3, velocities, robot.state, robot.now)
    assert expected in info.value.reason


def test_stream_rejected_when_not_ready() -> None:
    robot = SimRobot.create(THREE_LIMITS)
    robot.state.program_running = False
    with pytest.raises(GoalRejected, match="control program is not running"):
        robot.controller.stream_velocities(NAMES3, [0.0, 0.0, 0.1], robot.state, robot.now)
    with pytest.raises(GoalRejected, match="control program is not running"):
        robot.controller.stream_positions(NAMES3, [0.0, 0.0, 0.1], None, robot.state, robot.now)
