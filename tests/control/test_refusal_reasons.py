"""Refusals say what is wrong and what to do: ruckig's result codes, absurd numbers, a robot not ready."""

from __future__ import annotations

import math
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from ruckig import Result, Ruckig

from urdaemon.backends import MockBackend
from urdaemon.control import GoalStatus, MotionController, Tolerances, TrajectoryPoint
from urdaemon.control.ruckig_calls import (
    RUCKIG_RESULTS,
    calculate,
    new_input,
    ruckig_failure_reason,
    ruckig_result_reason,
)
from urdaemon.errors import GoalRejected
from urdaemon.model import UR_JOINTS, Lifecycle, RobotMode, SafetyMode

from .sim import PERIOD, UR10E_LIMITS, SimRobot

# ------------------------------------------------------------------ ruckig's result codes


def test_every_result_code_of_the_binding_and_of_ruckig_has_a_reason() -> None:
    for member in Result.__members__.values():
        assert int(member) in RUCKIG_RESULTS
    for code in (-101, -103, -104):  # codes ruckig returns that the 0.19 binding's enum lacks
        assert f"({code})" in ruckig_result_reason(code)
    assert ruckig_result_reason(-999) == "ruckig returned the unknown result code -999"


def test_a_trajectory_beyond_ruckigs_time_range_is_refused_with_a_reason() -> None:
    """Reproduction: ``move`` with a tiny velocity scale was refused with ``ruckig could not plan it: -101
    is not a valid Result`` (the binding's enum has no -101, so it raised ValueError with that text)."""
    inp = new_input(UR10E_LIMITS, velocity_scale=1e-6)
    inp.current_position = [0.0] * 6
    inp.target_position = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    with pytest.raises(GoalRejected) as info:
        calculate(Ruckig(6), inp, "move")
    reason = info.value.reason
    assert "not a valid" not in reason
    assert reason == (
        "move: ruckig could not plan it: it would last longer than ruckig's numerical time range, "
        "about 7 600 s (-101)"
    )


def test_ruckig_errors_become_reasons_without_its_input_dump() -> None:
    assert ruckig_failure_reason(ValueError("-101 is not a valid Result.")) == RUCKIG_RESULTS[-101]
    assert ruckig_failure_reason(ValueError("-7 is not a valid Result.")) == (
        "ruckig returned the unknown result code -7"
    )
    dump = "\n[ruckig] error in step 1, dof: 0 input: \ninp.current_position = [0]\n..."
    assert ruckig_failure_reason(RuntimeError(dump)) == RUCKIG_RESULTS[-110]
    invalid = "\n[ruckig] target velocity 3.000000 of DoF 0 exceeds its maximum velocity limit 2.000000."
    assert ruckig_failure_reason(RuntimeError(invalid)) == (
        "its input is invalid: target velocity 3.000000 of DoF 0 exceeds its maximum velocity limit "
        "2.000000. (-100)"
    )


@pytest.mark.parametrize(
    ("kwargs", "expected"),
    [
        ({"velocity_scale": 1e-6}, "longer than the longest goal, 7200 s"),
        ({"velocity_scale": 5e-324}, "longer than the longest goal, 7200 s"),
        ({"acceleration_scale": 1e-300}, "longer than the longest goal, 7200 s"),
        ({"acceleration_scale": 1e-12}, "longer than the longest goal, 7200 s"),
        ({"duration": 1e300}, "duration 1e+300 s exceeds the longest goal"),
    ],
)
def test_absurd_move_numbers_are_refused_clearly(kwargs: dict[str, Any], expected: str) -> None:
    """Reproduction: velocity_scale 1e-6 gave ``-101 is not a valid Result``; 1e-300 gave ruckig's
    ``[ruckig] error in step 1, dof: 0 input:``."""
    robot = SimRobot.create(UR10E_LIMITS)
    with pytest.raises(GoalRejected) as info:
        robot.controller.accept_move("m", UR_JOINTS, [1.0, 0, 0, 0, 0, 0], robot.state, 0.0, **kwargs)
    assert expected in info.value.reason
    assert "ruckig" not in info.value.reason


@settings(max_examples=60, deadline=None)
@given(
    velocity_scale=st.floats(min_value=5e-324, max_value=1.0),
    acceleration_scale=st.floats(min_value=5e-324, max_value=1.0),
    target=st.floats(min_value=-math.pi, max_value=math.pi),
    duration=st.none() | st.floats(min_value=1e-300, max_value=1e300),
)
def test_any_well_typed_move_is_planned_or_refused_with_a_reason(
    velocity_scale: float, acceleration_scale: float, target: float, duration: float | None
) -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    reason = ""
    try:
        robot.controller.accept_move(
            "m",
            UR_JOINTS,
            [target, 0, 0, 0, 0, 0],
            robot.state,
            0.0,
            duration=duration,
            velocity_scale=velocity_scale,
            acceleration_scale=acceleration_scale,
        )
    except GoalRejected as err:
        reason = err.reason
    assert "is not a valid" not in reason
    assert "input:" not in reason


@pytest.mark.parametrize(
    ("tolerances", "expected"),
    [
        (Tolerances(path=(1e9,) * 6), "path tolerance of shoulder_pan_joint is 1e+09, more than one turn"),
        (Tolerances(goal=(0.1,) * 5 + (1e308,)), "goal tolerance of wrist_3_joint is 1e+308"),
        (Tolerances(goal_time=1e300), "goal_time tolerance is 1e+300 s, more than the longest goal"),
    ],
)
def test_absurd_tolerances_are_refused(tolerances: Tolerances, expected: str) -> None:
    """Reproduction: path/goal tolerances of 1e9 were accepted (a check that can never fail)."""
    robot = SimRobot.create(UR10E_LIMITS)
    with pytest.raises(GoalRejected) as info:
        robot.controller.accept_move(
            "m", UR_JOINTS, [0.1, 0, 0, 0, 0, 0], robot.state, 0.0, tolerances=tolerances
        )
    assert expected in info.value.reason


def test_infinite_tolerances_still_switch_the_checks_off() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    inf = Tolerances(path=(math.inf,) * 6, goal=(math.inf,) * 6, goal_time=math.inf)
    robot.controller.accept_move("m", UR_JOINTS, [0.1, 0, 0, 0, 0, 0], robot.state, 0.0, tolerances=inf)
    assert robot.run_until_result("m", 2000).status is GoalStatus.SUCCEEDED


def test_huge_positions_are_refused_naming_the_limit() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    point = TrajectoryPoint((1e308, 0.0, 0.0, 0.0, 0.0, 0.0), 1.0)
    with pytest.raises(GoalRejected, match=r"shoulder_pan_joint position 1e\+308 is outside its limits"):
        robot.controller.accept_trajectory("t", UR_JOINTS, [point], robot.state, 0.0)


# ------------------------------------------------------------------ readiness


def _mock() -> tuple[MockBackend, MotionController]:
    backend = MockBackend("alice", UR_JOINTS, 500.0)
    state = backend.state
    state.lifecycle = Lifecycle.RUNNING
    state.robot_mode = RobotMode.RUNNING
    state.program_running = True
    return backend, MotionController(UR10E_LIMITS, period=PERIOD)


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        (
            {"lifecycle": Lifecycle.IDLE, "robot_mode": RobotMode.POWER_OFF},
            "robot is idle (robot mode POWER_OFF, safety mode NORMAL): the robot is powered off: "
            "call the startup service",
        ),
        (
            {"lifecycle": Lifecycle.IDLE, "robot_mode": RobotMode.IDLE},
            "robot is idle (robot mode IDLE, safety mode NORMAL): the brakes are engaged: call the startup "
            "service",
        ),
        (
            {"lifecycle": Lifecycle.PROTECTIVE_STOP, "safety_mode": SafetyMode.PROTECTIVE_STOP},
            "robot is protective_stop (robot mode RUNNING, safety mode PROTECTIVE_STOP): unlock the "
            "protective stop",
        ),
        (
            {"program_running": False},
            "control program is not running (robot mode RUNNING, safety mode NORMAL): call the "
            "resend_program service",
        ),
        (
            {"lifecycle": Lifecycle.EMERGENCY_STOP, "safety_mode": SafetyMode.ROBOT_EMERGENCY_STOP},
            "safety mode ROBOT_EMERGENCY_STOP): release the emergency stop, then call the startup service",
        ),
    ],
)
def test_not_ready_refusals_say_why_and_what_to_do(change: dict[str, object], expected: str) -> None:
    """Reproduction: after a power-off a goal was refused with only ``robot not ready: robot is idle``;
    without the control program with only ``control program is not running``."""
    backend, controller = _mock()
    for key, value in change.items():
        setattr(backend.state, key, value)
    with pytest.raises(GoalRejected) as info:
        controller.accept_move("m", UR_JOINTS, [0.1, 0, 0, 0, 0, 0], backend.state, 0.0)
    assert info.value.reason.startswith("robot not ready: ")
    assert expected in info.value.reason
    with pytest.raises(GoalRejected) as info:
        controller.stream_velocities(UR_JOINTS, [0.0] * 6, backend.state, 0.0)
    assert expected in info.value.reason


def test_the_backends_lifecycle_reason_is_the_advice() -> None:
    """The ur backend knows more (handed back, a lost link): its ``lifecycle_reason`` is what is said."""
    backend, controller = _mock()
    state = backend.state
    state.lifecycle = Lifecycle.IDLE
    state.robot_mode = RobotMode.POWER_OFF
    state.lifecycle_reason = "the robot is powered off: call startup, or power it on on the pendant"
    with pytest.raises(GoalRejected) as info:
        controller.accept_move("m", UR_JOINTS, [0.1, 0, 0, 0, 0, 0], state, 0.0)
    assert info.value.reason == (
        "robot not ready: robot is idle (robot mode POWER_OFF, safety mode NORMAL): the robot is powered "
        "off: call startup, or power it on on the pendant"
    )


def test_a_goal_aborted_by_a_power_off_says_why() -> None:
    """Reproduction: a goal aborted by a power-off mid-way ended with only ``robot is idle``."""
    robot = SimRobot.create(UR10E_LIMITS)
    robot.controller.accept_move("m", UR_JOINTS, [0.5, 0, 0, 0, 0, 0], robot.state, 0.0)
    for _ in range(10):
        robot.step()
    robot.state.lifecycle = Lifecycle.IDLE
    robot.state.robot_mode = RobotMode.POWER_OFF
    result = robot.run_until_result("m", 5)
    assert result.status is GoalStatus.ABORTED
    assert result.reason == (
        "robot is idle (robot mode POWER_OFF, safety mode NORMAL): the robot is powered off: call the "
        "startup service (or power it on on the pendant)"
    )
