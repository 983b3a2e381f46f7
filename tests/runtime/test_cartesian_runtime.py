"""runtime/cartesian.py without Zenoh: the mock robot stepped by hand, the controller ticked by hand.

Reproduction: before issue 17 runtime/cartesian.py did not exist (ImportError), so every test fails.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import pytest

from tests.integration.conftest import ROOT
from urdaemon.backends.base import Backend
from urdaemon.cell import parse_cell
from urdaemon.control import MotionController
from urdaemon.daemon import describe_cell, make_backend, twist_limits
from urdaemon.description.arm import arm_kinematics
from urdaemon.errors import GoalRejected
from urdaemon.model import Lifecycle, RobotMode, SafetyMode
from urdaemon.publish import codec
from urdaemon.runtime.cartesian import Cartesian
from urdaemon.runtime.gate import STOPPED_WHILE_PLANNING, MotionGate
from urdaemon.runtime.queries import Requests

CELL = """
cell: unit
robots:
  - name: alice
    model: ur5e
    backend: mock
    pose: {parent: world, xyz: [0.5, 0.0, 0.0]}
    mock: {initial_positions: [0.3, -1.8, 1.6, -1.4, -1.5708, 0.2]}
    motion: {cartesian: {max_speed: 0.5, speed: 0.1}}
"""


class _Goals:
    """What Cartesian sets on the robot's goals: the pose goal handler."""

    pose_goal = None


def _parts() -> tuple[Cartesian, MotionController, Backend, MotionGate]:
    cell = parse_cell(CELL, base_dir=ROOT / "configs")
    robot = cell.robot("alice")
    description = describe_cell(cell)
    limits = description.limits["alice"]
    backend = make_backend(robot, limits, None, cell.cell)
    state = backend.state
    state.lifecycle, state.robot_mode, state.safety_mode = (
        Lifecycle.RUNNING,
        RobotMode.RUNNING,
        SafetyMode.NORMAL,
    )
    state.program_running = True
    controller = MotionController(limits, period=backend.period)
    kin = arm_kinematics(robot, description.tree, limits.names, (limits.min_position, limits.max_position))
    controller.set_arm(kin, twist_limits(robot))
    gate = MotionGate(backend)
    log = logging.LoggerAdapter(logging.getLogger("test"), {})
    cartesian = Cartesian(robot, backend, controller, _Goals(), (gate, Requests()), kin, log)  # type: ignore[arg-type]
    return cartesian, controller, backend, gate


def _linear(pose: list[float], **fields: float) -> codec.LinearGoalMessage:
    return codec.decode_linear_goal(codec.encode({"poses": [pose], **fields}))


async def test_a_linear_goal_while_the_robot_still_decelerates_is_refused_as_moving() -> None:
    """A velocity stream stopped a moment ago: the robot is not busy (no goal, no live stream) but
    still slows down, so a linear goal, which starts from rest, is refused naming that."""
    cartesian, controller, backend, gate = _parts()
    state = backend.state
    now = 0.0
    controller.stream_velocities(controller.joint_names, [0.5, 0.0, 0.0, 0.0, 0.0, 0.0], state, now)
    for _ in range(100):  # 0.2 s at 500 Hz: at speed
        now += backend.period
        controller.tick(state, backend.command, now)
        backend.step()  # type: ignore[attr-defined]
    controller.stop("test", now)
    controller.tick(state, backend.command, now + backend.period)
    assert abs(state.velocities[0]) > 0.1, "still moving"
    pose = list(controller_tcp_pose(cartesian, state.positions))
    with pytest.raises(GoalRejected) as refused:
        await cartesian._plan(_linear(pose), gate.generation)
    assert refused.value.reason == "linear goal: the robot is moving; a linear goal starts from rest"


def controller_tcp_pose(cartesian: Cartesian, q: list[float]) -> tuple[float, ...]:
    kin = cartesian._arm("test")
    return tuple(kin.forward(q))


async def test_a_limit_above_its_cap_is_refused_naming_both_and_the_defaults_fill_the_rest() -> None:
    cartesian, _, _, _ = _parts()
    pose = [0.3, 0.1, 0.4, 3.1, 0.0, 0.0]
    limits = cartesian.limits(_linear(pose, jerk=2.0))
    assert (limits.speed, limits.jerk, limits.angular_speed) == (0.1, 2.0, 1.0)
    with pytest.raises(GoalRejected) as refused:
        cartesian.limits(_linear(pose, speed=0.6))
    assert refused.value.reason == (
        "linear goal.speed: 0.6 m/s is above the cap max_speed 0.5 m/s (the cell file's motion.cartesian)"
    )


async def test_a_plan_interrupted_between_slices_stops_at_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """What ends motion while a linear goal is planned (stop, cancel, freedrive) refuses it at its
    next slice, not after the whole plan: here a stop comes between the planning's start and its
    first slice."""
    from urdaemon.runtime import cartesian as module

    cartesian, _, backend, gate = _parts()
    pose = list(controller_tcp_pose(cartesian, backend.state.positions))
    pose[2] += 0.2
    slices = []

    async def stopped_first(step: Callable[[float], bool]) -> None:
        gate.interrupt_planning()  # as a stop does
        slices.append(step(float("inf")))  # the slice that follows refuses, at once

    monkeypatch.setattr(module, "sliced", stopped_first)
    with pytest.raises(GoalRejected) as refused:
        await cartesian._plan(_linear(pose), gate.generation)
    assert refused.value.reason == STOPPED_WHILE_PLANNING
    assert slices == []
