"""runtime/pose_goals.py without Zenoh: the mock robot stepped by hand, the controller ticked by hand.

Reproduction: before issue 17 runtime/pose_goals.py did not exist (ImportError), so every test fails;
before pose goals were solved in slices, Cartesian had no pose goal handler (the pose goal tests fail).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Sequence
from typing import cast

import pytest

from tests.integration.conftest import ROOT
from urdaemon.backends.base import Backend
from urdaemon.cell import parse_cell
from urdaemon.control import MotionController
from urdaemon.daemon import describe_cell, make_backend, twist_limits
from urdaemon.description.arm import arm_kinematics
from urdaemon.errors import GoalRejected
from urdaemon.model import Lifecycle, RobotMode, SafetyMode
from urdaemon.publish import envelope, linear_goal, move_goal
from urdaemon.runtime.gate import STOPPED_WHILE_PLANNING, MotionGate
from urdaemon.runtime.goals import Goals
from urdaemon.runtime.pose_goals import Cartesian
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
  - name: carol
    model: custom
    backend: mock
    pose: {xyz: [-1.0, 0.0, 0.0]}
    description: {xacro: servo_arm/servo_arm.urdf.xacro, macro: servo_arm}
    mock: {initial_positions: [0.3, 0.4, -0.5, 0.2]}
"""


class _Goals:
    """What Cartesian uses of the robot's goals: the pose goal handler, start_move and the answers."""

    def __init__(self, gate: MotionGate, requests: Requests) -> None:
        self._gate, self._requests = gate, requests  # what the real plan_in_task uses
        self.pose_goal: Callable[[object, move_goal.MoveGoalMessage], None] | None = None
        self.answers: list[tuple[str, object]] = []
        self.started: list[tuple[float, ...]] = []

    def start_move(self, goal: move_goal.MoveGoalMessage, positions: Sequence[float]) -> tuple[str, float]:
        self.started.append(tuple(positions))
        return "g1", 1.0

    def refuse(self, query: object, kind: str, err: Exception) -> None:
        self.answers.append(("refused", err.reason if isinstance(err, GoalRejected) else repr(err)))

    def accept(self, query: object, kind: str, goal_id: str, duration: float, extra: object = None) -> None:
        self.answers.append(("accepted", extra))

    plan_in_task = Goals.plan_in_task  # the real one, on this stub's gate, requests and answers


def _parts(name: str = "alice") -> tuple[Cartesian, MotionController, Backend, MotionGate]:
    cell = parse_cell(CELL, base_dir=ROOT / "configs")
    robot = cell.robot(name)
    description = describe_cell(cell)
    limits = description.limits[name]
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
    gate, requests = MotionGate(backend), Requests()
    log = logging.LoggerAdapter(logging.getLogger("test"), {})
    goals = _Goals(gate, requests)
    cartesian = Cartesian(robot, backend, controller, goals, gate, kin, log)  # type: ignore[arg-type]
    return cartesian, controller, backend, gate


def _linear(pose: list[float], **fields: float) -> linear_goal.LinearGoalMessage:
    return linear_goal.decode_linear_goal(envelope.encode({"poses": [pose], **fields}))


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
    from urdaemon.runtime import pose_goals as module

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


def _move(pose: Sequence[float], **fields: object) -> move_goal.MoveGoalMessage:
    return move_goal.decode_move_goal(envelope.encode({"pose": list(pose), **fields}))


class _Slices:
    """``sliced`` with a slice that has always run out of time: each runs one chunk of work."""

    def __init__(self) -> None:
        self.count = 0
        self.hold: asyncio.Event | None = None

    async def __call__(self, step: Callable[[float], bool]) -> None:
        while True:
            if self.hold is not None:
                await self.hold.wait()
            self.count += 1
            if not step(-1.0):
                return
            await asyncio.sleep(0)


async def _answered(cartesian: Cartesian, goal: move_goal.MoveGoalMessage) -> list[tuple[str, object]]:
    goals = _fake(cartesian)
    assert goals.pose_goal is not None
    goals.pose_goal(object(), goal)
    await asyncio.gather(*_fake(cartesian)._requests.tasks)
    return goals.answers


def _planning(gate: MotionGate) -> str | None:
    """What the gate says is being planned (read afresh)."""
    return gate.planning


def _fake(cartesian: Cartesian) -> _Goals:
    """The fake goals ``_parts`` gave ``cartesian``."""
    return cast(_Goals, cartesian._goals)


@pytest.mark.parametrize("name", ["alice", "carol"])
async def test_a_pose_goal_out_of_reach_is_solved_in_slices_and_refused_naming_it(
    name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The IK of a pose out of reach (a custom robot's nine numeric starts: 2-4 ms at once) runs one
    Newton evaluation per slice, between robot cycles; the refusal is the one it always was.
    Reproduction: before, the IK ran at once inside ``goal/move``'s handler (no ``pose_goal``)."""
    from urdaemon.runtime import pose_goals as module

    slices = _Slices()
    monkeypatch.setattr(module, "sliced", slices)
    cartesian, _, _, gate = _parts(name)
    answers = await _answered(cartesian, _move([5.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
    assert answers == [
        ("refused", "move goal: pose [5.0000, 0.0000, 0.0000, 0.0000, 0.0000, 0.0000] is out of reach")
    ]
    assert slices.count >= (50 if name == "carol" else 2)
    assert gate.planning is None


async def test_a_pose_goal_is_answered_with_the_joints_nearest_ik_gives(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from urdaemon.runtime import pose_goals as module

    monkeypatch.setattr(module, "sliced", _Slices())
    cartesian, controller, backend, _ = _parts("carol")
    kin = cartesian._arm("test")
    start = list(backend.state.positions)
    target = [v + 0.1 for v in start]
    pose = kin.forward(target, controller.tcp)
    answers = await _answered(cartesian, _move(pose))
    expected = kin.nearest(pose, start, controller.tcp)
    assert expected is not None
    assert answers == [("accepted", {"positions": list(expected)})]
    assert _fake(cartesian).started == [tuple(expected)]


async def test_a_pose_goal_being_solved_makes_goals_busy_and_a_stop_refuses_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from urdaemon.runtime import pose_goals as module

    slices = _Slices()
    slices.hold = asyncio.Event()
    monkeypatch.setattr(module, "sliced", slices)
    cartesian, _, _, gate = _parts("carol")
    goals = _fake(cartesian)
    assert goals.pose_goal is not None
    goals.pose_goal(object(), _move([5.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
    assert gate.planning == "pose move goal"
    goals.pose_goal(object(), _move([5.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
    assert goals.answers == [("refused", "busy: still planning pose move goal")]
    gate.interrupt_planning()  # as a stop or a cancel does
    slices.hold.set()
    await asyncio.gather(*_fake(cartesian)._requests.tasks)
    assert goals.answers[1:] == [("refused", STOPPED_WHILE_PLANNING)]
    assert slices.count == 1  # refused at its first slice, before any IK work
    assert _planning(gate) is None
    assert goals.started == []
