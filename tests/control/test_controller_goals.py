"""MotionController goals: execution, timing, tolerances, cancel, preempt, readiness, rejections."""

from __future__ import annotations

import itertools
import math
from typing import Any

import pytest

from urdaemon.control import (
    GoalFeedback,
    GoalResult,
    GoalStatus,
    MotionController,
    Tolerances,
    TrajectoryPoint,
)
from urdaemon.errors import GoalRejected
from urdaemon.model import UR_JOINTS, CommandMode, JointCommand, Lifecycle, SafetyMode

from .sim import PERIOD, THREE_LIMITS, UR10E_LIMITS, SimRobot, check_command_limits, ready_state

UR_POINTS = [
    TrajectoryPoint((0.5, -0.5, 1.0, 0.2, -0.3, 1.5), 2.0),
    TrajectoryPoint((1.0, -1.0, 2.0, 0.4, -0.6, 3.0), 4.0),
    TrajectoryPoint((0.2, -0.2, 0.4, 0.1, 0.0, 0.5), 7.0),
]


def test_trajectory_succeeds_in_the_planned_number_of_cycles() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    duration = robot.controller.accept_trajectory("g1", UR_JOINTS, UR_POINTS, robot.state, robot.now)
    assert duration == pytest.approx(7.0)
    active_before = robot.controller.active_goal_id
    assert active_before == "g1"
    result = robot.run_until_result("g1", 5000)
    assert result.status is GoalStatus.SUCCEEDED
    assert result.reason == "reached the goal within tolerance"
    assert result.duration == pytest.approx(7.0)
    # 3500 cycles of trajectory, then one more for the robot to report the final point.
    assert robot.controller.statistics().ticks == round(7.0 / PERIOD) + 1
    assert result.final_positions == pytest.approx(UR_POINTS[-1].positions, abs=1e-9)
    assert max(abs(e) for e in result.final_error) < 1e-9
    assert robot.controller.active_goal_id is None
    # At rest on the goal, the controller goes idle in the same cycle.
    assert robot.controller.mode == "idle"
    assert robot.commands[-1][0] is CommandMode.IDLE
    assert robot.commands[-2][0] is CommandMode.POSITION
    stats = robot.controller.statistics()
    assert (stats.goals_accepted, stats.goals_succeeded, stats.goals_aborted) == (1, 1, 0)


def test_waypoints_are_passed_at_their_times() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    robot.controller.accept_trajectory("g1", UR_JOINTS, UR_POINTS, robot.state, robot.now)
    robot.run_until_result("g1", 5000)
    for pt in UR_POINTS:
        cycle = round(pt.time_from_start / PERIOD) - 1  # the command of cycle k is at t = (k + 1)·period
        # Trajectory time is accumulated cycle by cycle, so allow float round-off.
        assert robot.commands[cycle][1] == pytest.approx(pt.positions, abs=1e-6)


def test_speed_scaling_half_doubles_the_cycles() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    robot.state.speed_scaling = 0.5
    robot.controller.accept_trajectory("g1", UR_JOINTS, UR_POINTS, robot.state, robot.now)
    result = robot.run_until_result("g1", 9000)
    assert result.status is GoalStatus.SUCCEEDED
    assert result.duration == pytest.approx(7.0)
    assert robot.controller.statistics().ticks == 2 * round(7.0 / PERIOD) + 1
    # Commanded velocities are scaled too, so they stay consistent with the slower positions.
    mode, pos, vel = robot.commands[2000]
    _, prev_pos, _ = robot.commands[1999]
    assert mode is CommandMode.POSITION
    for i in range(6):
        assert (pos[i] - prev_pos[i]) / PERIOD == pytest.approx(vel[i], abs=0.02)


def test_speed_scaling_zero_pauses_the_goal() -> None:
    # The time scaling ramps down (a step would jerk the arm), then trajectory time stands still.
    robot = SimRobot.create(UR10E_LIMITS)
    robot.controller.accept_trajectory("g1", UR_JOINTS, UR_POINTS, robot.state, robot.now)
    for _ in range(100):
        robot.step()
    robot.state.speed_scaling = 0.0
    for _ in range(2000):
        robot.step()
        if robot.commands[-1][2] == (0.0,) * 6:
            break
    held = robot.commands[-1][1]
    for _ in range(100):
        robot.step()
    assert robot.commands[-1][1] == held
    assert robot.commands[-1][2] == (0.0,) * 6
    assert robot.results() == []
    robot.state.speed_scaling = 1.0
    assert robot.run_until_result("g1", 10_000).status is GoalStatus.SUCCEEDED


def test_feedback_first_tick_then_at_most_every_feedback_period() -> None:
    robot = SimRobot.create(UR10E_LIMITS, feedback_period=0.1)
    robot.controller.accept_trajectory("g1", UR_JOINTS, UR_POINTS, robot.state, robot.now)
    robot.step()
    first = robot.feedback()
    assert len(first) == 1
    assert first[0].goal_id == "g1"
    assert first[0].time_from_start == 0.0
    assert first[0].progress == 0.0
    robot.run_until_result("g1", 5000)
    feedback = robot.feedback()
    # 7 s at one per 0.1 s plus the settle cycle.
    assert 70 <= len(feedback) <= 72
    stamps = [fb.time_from_start for fb in feedback]
    assert stamps == sorted(stamps)
    assert all(b - a >= 0.1 - 1e-9 for a, b in itertools.pairwise(stamps))
    for fb in feedback:
        assert 0.0 <= fb.progress <= 1.0
        assert fb.duration == pytest.approx(7.0)
        assert fb.error == pytest.approx(tuple(d - a for d, a in zip(fb.desired, fb.actual, strict=True)))
    # The result is the last event of the goal.
    assert isinstance(robot.events[-1], GoalResult)
    assert feedback[-1].progress > 0.98


def test_path_tolerance_abort_names_joint_error_and_tolerance() -> None:
    robot = SimRobot.create(UR10E_LIMITS, path_tolerance=0.05)
    robot.controller.accept_trajectory("g1", UR_JOINTS, UR_POINTS, robot.state, robot.now)
    for _ in range(500):
        robot.step()
    robot.following = False  # the robot is blocked
    result = robot.run_until_result("g1", 1000)
    assert result.status is GoalStatus.ABORTED
    assert "path tolerance violated" in result.reason
    assert "wrist_3_joint" in result.reason  # the fastest-moving joint leaves the tolerance first
    assert "tolerance 0.05" in result.reason
    error = float(result.reason.split(" is ")[1].split(" ")[0])
    assert abs(error) >= 0.05  # printed to 4 digits
    assert robot.commands[-1][0] is CommandMode.IDLE
    assert robot.controller.mode == "idle"


def test_per_goal_path_tolerances_apply() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    tight = Tolerances(path=(1.0, 1.0, 1.0, 1.0, 1.0, 0.01))
    robot.controller.accept_trajectory("g1", UR_JOINTS, UR_POINTS, robot.state, robot.now, tolerances=tight)
    for _ in range(200):
        robot.step()
    robot.following = False
    result = robot.run_until_result("g1", 100)
    assert "wrist_3_joint" in result.reason
    assert "tolerance 0.01" in result.reason


def test_goal_time_abort_when_goal_tolerance_is_never_reached() -> None:
    robot = SimRobot.create(UR10E_LIMITS, goal_tolerance=0.01)
    robot.offset = [0.0, 0.0, 0.0, 0.03, 0.0, 0.0]  # wrist_1 settles 3 cm-rad off
    tolerances = Tolerances(goal_time=0.5)
    robot.controller.accept_trajectory(
        "g1", UR_JOINTS, UR_POINTS, robot.state, robot.now, tolerances=tolerances
    )
    result = robot.run_until_result("g1", 5000)
    assert result.status is GoalStatus.ABORTED
    assert "goal tolerance not reached 0.5 s after the planned end" in result.reason
    assert "wrist_1_joint" in result.reason
    assert "tolerance 0.01" in result.reason
    # Planned end at cycle 3500 (now 6.998), aborted once now exceeds that by more than 0.5 s.
    ticks = robot.controller.statistics().ticks
    assert ticks == 3500 + 251
    assert result.final_error[3] == pytest.approx(-0.03)


def test_goal_tolerance_per_goal_lets_it_succeed() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    robot.offset = [0.0, 0.0, 0.0, 0.03, 0.0, 0.0]
    tolerances = Tolerances(goal=(0.01, 0.01, 0.01, 0.05, 0.01, 0.01))
    robot.controller.accept_trajectory(
        "g1", UR_JOINTS, UR_POINTS, robot.state, robot.now, tolerances=tolerances
    )
    assert robot.run_until_result("g1", 5000).status is GoalStatus.SUCCEEDED


def test_cancel_ends_canceled_now_and_stops_smoothly() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    robot.controller.accept_trajectory("g1", UR_JOINTS, UR_POINTS, robot.state, robot.now)
    for _ in range(600):
        robot.step()
    assert robot.controller.cancel("other") is False
    assert robot.controller.cancel("g1") is True
    assert robot.controller.cancel("g1") is False
    robot.events.extend(robot.controller.drain_events())
    results = robot.results()
    assert [(r.goal_id, r.status) for r in results] == [("g1", GoalStatus.CANCELED)]
    assert results[0].reason == "canceled by request"
    assert results[0].duration == pytest.approx(600 * PERIOD)
    assert robot.controller.active_goal_id is None
    assert robot.controller.mode == "stopping"
    ticks = robot.run_until_idle(1000)
    assert ticks > 10  # it was moving fast: a real ramp, not a jump
    check_command_limits(robot.commands, UR10E_LIMITS, PERIOD)
    assert len(robot.results()) == 1
    assert robot.controller.statistics().goals_canceled == 1


def test_cancel_without_goal_returns_false() -> None:
    controller = MotionController(UR10E_LIMITS, period=PERIOD)
    assert controller.cancel() is False
    assert controller.cancel("g1") is False
    assert controller.drain_events() == []


def test_stop_aborts_goal_with_reason_then_ramps_down() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    robot.controller.accept_trajectory("g1", UR_JOINTS, UR_POINTS, robot.state, robot.now)
    for _ in range(600):
        robot.step()
    robot.controller.stop("operator pressed stop", robot.now)
    robot.run_until_idle(1000)
    (result,) = robot.results()
    assert result.status is GoalStatus.ABORTED
    assert result.reason == "operator pressed stop"
    check_command_limits(robot.commands, UR10E_LIMITS, PERIOD)


def test_preempt_is_continuous_and_names_the_new_goal() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    controller = robot.controller
    controller.accept_trajectory("g1", UR_JOINTS, UR_POINTS, robot.state, robot.now)
    for _ in range(700):
        robot.step()
    with pytest.raises(GoalRejected) as info:
        controller.accept_move("g2", UR_JOINTS, [0.0] * 6, robot.state, robot.now)
    assert info.value.reason == "busy: goal g1 is executing"
    controller.accept_move(
        "g2", UR_JOINTS, [-0.5, 0.3, -1.0, 0.0, 0.5, -1.0], robot.state, robot.now, preempt=True
    )
    robot.events.extend(controller.drain_events())
    (first,) = robot.results()
    assert first.goal_id == "g1"
    assert first.status is GoalStatus.PREEMPTED
    assert "g2" in first.reason
    assert controller.active_goal_id == "g2"
    result = robot.run_until_result("g2", 5000)
    assert result.status is GoalStatus.SUCCEEDED
    assert result.final_positions == pytest.approx((-0.5, 0.3, -1.0, 0.0, 0.5, -1.0), abs=1e-9)
    # No velocity jump across the switch: the limit check covers every cycle, including it.
    check_command_limits(robot.commands, UR10E_LIMITS, PERIOD)
    before, after = robot.commands[699][2], robot.commands[700][2]
    assert max(abs(a - b) for a, b in zip(before, after, strict=True)) < 5.0 * PERIOD * 1.05
    stats = controller.statistics()
    assert (stats.goals_accepted, stats.goals_preempted, stats.goals_succeeded) == (2, 1, 1)


def test_rejected_preempt_leaves_the_running_goal_alone() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    robot.controller.accept_trajectory("g1", UR_JOINTS, UR_POINTS, robot.state, robot.now)
    for _ in range(100):
        robot.step()
    with pytest.raises(GoalRejected, match="outside its limits"):
        robot.controller.accept_move(
            "g2", UR_JOINTS, [0.0, 0.0, 4.0, 0.0, 0.0, 0.0], robot.state, robot.now, preempt=True
        )
    assert robot.controller.active_goal_id == "g1"
    assert robot.controller.drain_events() == []
    assert robot.run_until_result("g1", 5000).status is GoalStatus.SUCCEEDED


def test_same_goal_id_cannot_preempt_itself() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    robot.controller.accept_trajectory("g1", UR_JOINTS, UR_POINTS, robot.state, robot.now)
    with pytest.raises(GoalRejected, match="goal g1 is already executing"):
        robot.controller.accept_trajectory("g1", UR_JOINTS, UR_POINTS, robot.state, robot.now, preempt=True)


def test_not_ready_aborts_then_new_motion_seeds_from_measured_pose() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    controller = robot.controller
    controller.accept_trajectory("g1", UR_JOINTS, UR_POINTS, robot.state, robot.now)
    for _ in range(800):
        robot.step()
    robot.state.program_running = False
    robot.step()
    (result,) = robot.results()
    assert result.status is GoalStatus.ABORTED
    assert result.reason.startswith("control program is not running (robot mode ")
    assert robot.commands[-1][0] is CommandMode.IDLE
    assert controller.mode == "idle"
    # While not ready, new goals are refused with the robot's own reason.
    with pytest.raises(GoalRejected, match="control program is not running"):
        controller.accept_move("g2", UR_JOINTS, [0.0] * 6, robot.state, robot.now)
    # Someone moves the arm by hand; the stale setpoint must not be resumed.
    moved = [0.3, -0.2, 0.1, 0.0, 0.0, 0.0]
    robot.state.positions[:] = moved
    robot.state.program_running = True
    robot.step()
    assert robot.commands[-1] == (CommandMode.IDLE, tuple(moved), (0.0,) * 6)
    controller.accept_move("g2", UR_JOINTS, [0.35, -0.2, 0.1, 0.0, 0.0, 0.0], robot.state, robot.now)
    robot.step()
    first_pos = robot.commands[-1][1]
    assert max(abs(a - b) for a, b in zip(first_pos, moved, strict=True)) < 1e-4
    assert robot.run_until_result("g2", 2000).status is GoalStatus.SUCCEEDED


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ({"lifecycle": Lifecycle.PROTECTIVE_STOP}, "robot is protective_stop"),
        ({"safety_mode": SafetyMode.PROTECTIVE_STOP}, "robot safety mode is PROTECTIVE_STOP"),
    ],
)
def test_not_ready_reasons_are_passed_through(change: dict[str, object], reason: str) -> None:
    robot = SimRobot.create(THREE_LIMITS)
    robot.controller.accept_move("g1", ("a", "b", "c"), [0.5, 0.5, 0.2], robot.state, robot.now)
    robot.step()
    for key, value in change.items():
        setattr(robot.state, key, value)
    robot.step()
    (result,) = robot.results()
    assert result.status is GoalStatus.ABORTED
    assert result.reason.startswith(f"{reason} (robot mode ")


def test_move_goal_timing_and_scales() -> None:
    robot = SimRobot.create(THREE_LIMITS)
    duration = robot.controller.accept_move(
        "m1", ("c", "b", "a"), [0.0, 0.0, 0.5], robot.state, robot.now, duration=1.5
    )
    assert duration == 1.5
    result = robot.run_until_result("m1", 2000)
    assert result.status is GoalStatus.SUCCEEDED
    assert result.final_positions == pytest.approx((0.5, 0.0, 0.0), abs=1e-9)
    assert robot.controller.statistics().ticks == 750 + 1
    fast = robot.controller.accept_move("m2", ("a", "b", "c"), [-0.5, 0.0, 0.0], robot.state, robot.now)
    robot.run_until_result("m2", 2000)
    slow = robot.controller.accept_move(
        "m3",
        ("a", "b", "c"),
        [0.5, 0.0, 0.0],
        robot.state,
        robot.now,
        velocity_scale=0.25,
        acceleration_scale=0.5,
    )
    assert slow > fast
    robot.run_until_result("m3", 3000)
    check_command_limits(robot.commands, THREE_LIMITS, PERIOD)


def test_move_to_current_pose_succeeds_at_once() -> None:
    robot = SimRobot.create(THREE_LIMITS, positions=[0.1, 0.2, 0.3])
    assert robot.controller.accept_move("m1", ("a", "b", "c"), [0.1, 0.2, 0.3], robot.state, robot.now) == 0.0
    result = robot.run_until_result("m1", 3)
    assert result.status is GoalStatus.SUCCEEDED
    assert result.duration == 0.0


NAMES3 = ("a", "b", "c")


@pytest.mark.parametrize(
    ("names", "points", "kwargs", "expected"),
    [
        (("a", "b", "x"), [TrajectoryPoint((0.1, 0.0, 0.0), 1.0)], {}, "unknown joint(s) 'x'"),
        (("a", "b"), [TrajectoryPoint((0.1, 0.0), 1.0)], {}, "missing joint(s) 'c'"),
        (("a", "b", "b"), [TrajectoryPoint((0.1, 0.0, 0.0), 1.0)], {}, "joint 'b' is listed twice"),
        (NAMES3, [TrajectoryPoint((0.1, 0.0), 1.0)], {}, "point 0 positions has 2 values for 3 joints"),
        (NAMES3, [], {}, "the trajectory has no points"),
        (NAMES3, [TrajectoryPoint((0.1, math.nan, 0.0), 1.0)], {}, "point 0 positions: b is nan"),
        (NAMES3, [TrajectoryPoint((0.1, 0.0, 0.0), 0.0)], {}, "point 0: time_from_start must be > 0"),
        (
            NAMES3,
            [TrajectoryPoint((0.1, 0.0, 0.0), 2.0), TrajectoryPoint((0.2, 0.0, 0.0), 1.0)],
            {},
            "point 1: time_from_start 1 s is not after point 0's 2 s",
        ),
        (
            NAMES3,
            [TrajectoryPoint((0.1, 0.0, 0.9), 1.0)],
            {},
            "point 0: c position 0.9 is outside its limits",
        ),
        (
            NAMES3,
            [TrajectoryPoint((0.1, 0.0, 0.0), 1.0, velocities=(2.5, 0.0, 0.0))],
            {},
            "point 0: a velocity 2.5 exceeds its limit 2",
        ),
        (NAMES3, [TrajectoryPoint((0.9, 0.0, 0.0), 0.2)], {}, "point 0: reaching it needs at least"),
        (
            NAMES3,
            [TrajectoryPoint((0.1, 0.0, 0.0), 1.0)],
            {"tolerances": Tolerances(path=(0.1, 0.1))},
            "path tolerances have 2 values for 3 joints",
        ),
        (
            NAMES3,
            [TrajectoryPoint((0.1, 0.0, 0.0), 1.0)],
            {"tolerances": Tolerances(goal=(0.1, 0.0, 0.1))},
            "goal tolerance of b must be > 0",
        ),
        (
            NAMES3,
            [TrajectoryPoint((0.1, 0.0, 0.0), 1.0)],
            {"tolerances": Tolerances(goal_time=-1.0)},
            "goal_time tolerance must be >= 0",
        ),
    ],
)
def test_trajectory_rejections_name_the_problem(
    names: tuple[str, ...], points: list[TrajectoryPoint], kwargs: dict[str, Any], expected: str
) -> None:
    robot = SimRobot.create(THREE_LIMITS)
    with pytest.raises(GoalRejected) as info:
        robot.controller.accept_trajectory("g1", names, points, robot.state, robot.now, **kwargs)
    assert expected in info.value.reason
    assert robot.controller.active_goal_id is None
    assert robot.controller.statistics().goals_accepted == 0


@pytest.mark.parametrize(
    ("positions", "kwargs", "expected"),
    [
        ([0.1, 0.0, math.inf], {}, "target: c is inf"),
        ([0.1, 0.0, 0.0, 0.0], {}, "positions has 4 values for 3 joints"),
        ([1.5, 0.0, 0.0], {}, "target: a position 1.5 is outside its limits [-1, 1]"),
        ([0.1, 0.0, 0.0], {"duration": 0.0}, "duration must be a finite number > 0"),
        ([0.9, 0.0, 0.0], {"duration": 0.3}, "move needs at least"),
        ([0.1, 0.0, 0.0], {"velocity_scale": 0.0}, "velocity_scale must be in (0, 1]"),
        ([0.1, 0.0, 0.0], {"acceleration_scale": 2.0}, "acceleration_scale must be in (0, 1]"),
    ],
)
def test_move_rejections_name_the_problem(
    positions: list[float], kwargs: dict[str, Any], expected: str
) -> None:
    robot = SimRobot.create(THREE_LIMITS)
    with pytest.raises(GoalRejected) as info:
        robot.controller.accept_move("m1", NAMES3, positions, robot.state, robot.now, **kwargs)
    assert expected in info.value.reason


def test_feedback_types_and_results_are_drained_once() -> None:
    controller = MotionController(THREE_LIMITS, period=PERIOD)
    state = ready_state(NAMES3)
    command = JointCommand.idle(3)
    controller.accept_move("m1", NAMES3, [0.2, 0.0, 0.0], state, 0.0)
    controller.tick(state, command, 0.0)
    events = controller.drain_events()
    assert len(events) == 1
    assert isinstance(events[0], GoalFeedback)
    assert controller.drain_events() == []


def test_idle_command_reports_measured_pose() -> None:
    controller = MotionController(THREE_LIMITS, period=PERIOD)
    state = ready_state(NAMES3, [0.1, -0.2, 0.3])
    command = JointCommand(CommandMode.POSITION, [9.0, 9.0, 9.0], [1.0, 1.0, 1.0])
    controller.tick(state, command, 0.0)
    assert command.mode is CommandMode.IDLE
    assert command.positions == [0.1, -0.2, 0.3]
    assert command.velocities == [0.0, 0.0, 0.0]
    assert controller.statistics().ticks == 1


def test_constructor_validates_parameters() -> None:
    with pytest.raises(ValueError, match="period must be > 0"):
        MotionController(THREE_LIMITS, period=0.0)
    with pytest.raises(ValueError, match="goal_time_tolerance must be >= 0"):
        MotionController(THREE_LIMITS, period=PERIOD, goal_time_tolerance=-1.0)
    assert MotionController(THREE_LIMITS, period=PERIOD).joint_names == NAMES3


def test_abort_ends_the_goal_at_once_goes_idle_and_the_next_motion_starts_from_the_measured_pose() -> None:
    sim = SimRobot.create(THREE_LIMITS)
    sim.controller.accept_move("g1", THREE_LIMITS.names, [0.8, 0.0, 0.0], sim.state, sim.now, duration=2.0)
    for _ in range(300):
        sim.step()
    assert sim.state.velocities[0] != 0.0
    sim.controller.abort("backend failed: link lost")
    sim.events.extend(sim.controller.drain_events())
    (result,) = sim.results()
    assert result.status is GoalStatus.ABORTED
    assert result.reason == "backend failed: link lost"
    assert sim.controller.mode == "idle"
    # the robot was moved elsewhere while the link was down; no ramp from the old setpoint follows
    sim.state.positions[:] = [0.1, 0.2, 0.0]
    sim.state.velocities[:] = [0.0, 0.0, 0.0]
    sim.step()
    mode, positions, _ = sim.commands[-1]
    assert mode is CommandMode.IDLE
    assert list(positions) == pytest.approx([0.1, 0.2, 0.0])
    sim.controller.accept_move("g2", THREE_LIMITS.names, [0.2, 0.2, 0.0], sim.state, sim.now, duration=1.0)
    sim.step()
    _, first, _ = sim.commands[-1]
    assert first[0] == pytest.approx(0.1, abs=1e-3), "the new goal starts at the measured pose"


def test_a_preempt_that_could_not_continue_the_motion_at_low_speed_scaling_is_refused() -> None:
    sim = SimRobot.create(THREE_LIMITS)
    sim.state.speed_scaling = 0.1
    for _ in range(200):
        sim.controller.stream_velocities(THREE_LIMITS.names, [1.0, 0.0, 0.0], sim.state, sim.now)
        sim.step()
    assert sim.state.velocities[0] == pytest.approx(1.0)
    with pytest.raises(GoalRejected, match=r"cannot take over the current motion at speed scaling 0\.1"):
        sim.controller.accept_move(
            "g", THREE_LIMITS.names, [0.5, 0.0, 0.0], sim.state, sim.now, duration=3.0, preempt=True
        )
    sim.state.speed_scaling = 1.0
    duration = sim.controller.accept_move(
        "g", THREE_LIMITS.names, [0.9, 0.0, 0.0], sim.state, sim.now, duration=3.0, preempt=True
    )
    assert duration == pytest.approx(3.0)
    before = sim.state.velocities[0]
    sim.step()
    assert sim.state.velocities[0] == pytest.approx(before, abs=5.0 * 0.002 * 1.05), "no velocity jump"


def _lagging_step(robot: SimRobot, gain: float) -> None:
    """One cycle of a robot that closes ``gain`` of its distance to the commanded position per cycle
    (a UR's servoj lags like this), not landing on it."""
    robot.controller.tick(robot.state, robot.command, robot.now)
    robot.commands.append((robot.command.mode, tuple(robot.command.positions), ()))
    if robot.command.mode is CommandMode.POSITION:
        for i, target in enumerate(robot.command.positions):
            step = gain * (target - robot.state.positions[i])
            robot.state.positions[i] += step
            robot.state.velocities[i] = step / PERIOD
    else:
        robot.state.velocities[:] = [0.0] * len(robot.state.velocities)
    robot.events.extend(robot.controller.drain_events())
    robot.now += PERIOD


def test_after_a_goal_the_final_setpoint_is_held_until_a_lagging_robot_settles_on_it() -> None:
    """The goal succeeds within its tolerance while the robot still lags; the controller keeps sending
    the final point until the robot rests on it (within SETTLE_POSITION), and only then goes idle. Before
    it held (972271b) it went idle at once and the robot stopped where the lag had it."""
    from urdaemon.control.stopping import SETTLE_POSITION

    robot = SimRobot.create(UR10E_LIMITS)
    goal = [0.3, -0.2, 0.1, 0.0, 0.0, 0.0]
    robot.controller.accept_trajectory("g1", UR_JOINTS, [TrajectoryPoint(tuple(goal), 1.0)], robot.state, 0.0)
    for _ in range(2000):
        _lagging_step(robot, 0.1)
        if robot.controller.mode == "idle":
            break
    (result,) = robot.results()
    assert result.status is GoalStatus.SUCCEEDED
    assert robot.controller.mode == "idle"
    assert robot.state.positions == pytest.approx(goal, abs=2 * SETTLE_POSITION)
    idle_at = next(k for k, c in enumerate(robot.commands) if c[0] is CommandMode.IDLE)
    assert all(c[0] is CommandMode.POSITION for c in robot.commands[:idle_at])
    assert idle_at > round(1.0 / PERIOD) + 10, "held for the robot, not let go at the goal's end"


def test_a_robot_that_never_settles_is_let_go_after_the_settle_time() -> None:
    """A robot that stays off its setpoint (a steady error) is held at most SETTLE_TIME after the stop."""
    from urdaemon.control.stopping import SETTLE_TIME

    robot = SimRobot.create(UR10E_LIMITS)
    robot.offset = [1e-3] + [0.0] * 5  # always 1 mrad off what it is told
    robot.controller.accept_trajectory(
        "g1", UR_JOINTS, [TrajectoryPoint((0.1, 0.0, 0.0, 0.0, 0.0, 0.0), 0.5)], robot.state, 0.0
    )
    robot.run_until_result("g1", 1000)
    ticks = robot.run_until_idle(round(2 * SETTLE_TIME / PERIOD))
    assert ticks == pytest.approx(SETTLE_TIME / PERIOD, abs=2)


def test_a_cancel_lets_go_when_its_ramp_ends_even_if_the_robot_is_off_the_point() -> None:
    """Only a succeeded goal's final point is held for the robot to settle: after a cancel (or a stop,
    or the deadman) the controller goes idle when its stop ramp ends, so a robot that cannot reach the
    point (blocked, in force mode) is not pushed toward it."""
    robot = SimRobot.create(UR10E_LIMITS)
    robot.offset = [1e-3] + [0.0] * 5  # always 1 mrad off what it is told
    robot.controller.accept_trajectory(
        "g1", UR_JOINTS, [TrajectoryPoint((0.5, 0.0, 0.0, 0.0, 0.0, 0.0), 2.0)], robot.state, 0.0
    )
    for _ in range(200):
        robot.step()
    assert robot.controller.cancel("g1")
    ticks = robot.run_until_idle(2000)
    (result,) = robot.results()
    assert result.status is GoalStatus.CANCELED
    assert ticks < 400, "let go as the stop ramp ended (it takes well under 0.8 s from this speed)"


def test_freedrive_or_passthrough_right_after_a_goal_releases_the_hold() -> None:
    """While a succeeded goal's final point is held for a lagging robot, release_hold (what freedrive and
    a passthrough start call) goes idle at once, so they are not refused as busy."""
    robot = SimRobot.create(UR10E_LIMITS)
    robot.offset = [1e-3] + [0.0] * 5
    robot.controller.accept_trajectory(
        "g1", UR_JOINTS, [TrajectoryPoint((0.1, 0.0, 0.0, 0.0, 0.0, 0.0), 0.5)], robot.state, 0.0
    )
    robot.run_until_result("g1", 1000)
    robot.step()
    assert robot.controller.mode == "stopping", "held for the robot to settle"
    robot.controller.release_hold()
    assert robot.controller.mode == "idle"
