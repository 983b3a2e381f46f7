"""runtime/pose_goals.py without Zenoh: the mock robot stepped by hand, the controller ticked by hand;
pose move goals through the runtime's goals (runtime/goals.py), on a fake node with fake queries.

Reproduction: before issue 17 runtime/pose_goals.py did not exist (ImportError), so every test fails;
before pose goals were solved in slices, Cartesian had no pose goal handler (the pose goal tests fail).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Generator, Sequence
from typing import Any

import pytest

from tests.integration.conftest import ROOT
from tests.integration.test_review_planning import Node, Query
from urdaemon.backends.base import Backend
from urdaemon.cell import parse_cell
from urdaemon.control import MotionController
from urdaemon.daemon import describe_cell, make_backend, twist_limits
from urdaemon.description.arm import arm_kinematics
from urdaemon.errors import GoalRejected
from urdaemon.model import Lifecycle, RobotMode, SafetyMode
from urdaemon.publish import envelope, linear_goal, move_goal
from urdaemon.robot import RobotRuntime
from urdaemon.runtime import slicing
from urdaemon.runtime.motion import STOPPED_WHILE_PLANNING, How, RobotMotion
from urdaemon.runtime.pose_goals import Cartesian

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


def _parts(name: str = "alice") -> tuple[Cartesian, MotionController, Backend, RobotRuntime]:
    """``name``'s Cartesian goals' work, its controller and mock backend (ready), and its runtime
    (declared on a fake node, not running: its cycles are stepped by hand)."""
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
    log = logging.LoggerAdapter(logging.getLogger("test"), {})
    cartesian = Cartesian(robot=robot, backend=backend, controller=controller, kinematics=kin, log=log)
    node: Any = Node()
    runtime = RobotRuntime(cell.cell, robot, backend, controller, node, cell.publish, arm=kin)
    runtime.declare()
    return cartesian, controller, backend, runtime


def _linear(pose: list[float], **fields: float) -> linear_goal.LinearGoalMessage:
    return linear_goal.decode_linear_goal(envelope.encode({"poses": [pose], **fields}))


async def test_a_linear_goal_while_the_robot_still_decelerates_is_refused_as_moving() -> None:
    """A velocity stream stopped a moment ago: the robot is not busy (no goal, no live stream) but
    still slows down, so a linear goal, which starts from rest, is refused naming that."""
    cartesian, controller, backend, _ = _parts()
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
    goal = _linear(pose)
    with pytest.raises(GoalRejected) as refused:
        cartesian.linear_steps(goal, *cartesian.linear_targets(goal))
    assert refused.value.reason == "linear goal: the robot is moving; a linear goal starts from rest"


def controller_tcp_pose(cartesian: Cartesian, q: list[float]) -> tuple[float, ...]:
    return tuple(cartesian._kin.forward(q))


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


async def test_a_plan_interrupted_between_slices_stops_at_once() -> None:
    """What ends motion while a linear goal is planned (stop, cancel, freedrive) refuses it at its
    next slice, not after the whole plan: here a stop comes between the planning's start and its
    first slice."""
    cartesian, _, backend, runtime = _parts()
    motion: RobotMotion = runtime.motion
    pose = list(controller_tcp_pose(cartesian, backend.state.positions))
    pose[2] += 0.2
    goal = _linear(pose)
    steps_run = 0

    def counted(steps: Generator[None, None, Any]) -> Generator[None, None, Any]:
        nonlocal steps_run
        while True:
            steps_run += 1
            try:
                next(steps)
            except StopIteration as stop:
                return stop.value
            yield

    with motion.claim("linear goal being decoded") as ticket:
        steps = counted(cartesian.linear_steps(goal, *cartesian.linear_targets(goal)))
        motion.end("stop requested", How.STOP)  # as a stop does
        with pytest.raises(GoalRejected) as refused:
            await motion.plan(ticket, steps, what="linear goal of 1 pose", from_rest=True)
    assert refused.value.reason == STOPPED_WHILE_PLANNING
    assert steps_run == 0
    assert motion.planning is None
    assert not motion.from_rest


def _move(pose: Sequence[float], **fields: object) -> move_goal.MoveGoalMessage:
    return move_goal.decode_move_goal(envelope.encode({"pose": list(pose), **fields}))


class _Slices:
    """``sliced`` with a slice that has always run out of time: each runs one step of work."""

    def __init__(self) -> None:
        self.count = 0
        self.hold: asyncio.Event | None = None

    async def __call__(self, steps: Generator[None, None, Any], check: Any = None) -> Any:
        while True:
            if self.hold is not None:
                await self.hold.wait()
            self.count += 1
            if check is not None:
                check()
            try:
                next(steps)
            except StopIteration as stop:
                return stop.value
            await asyncio.sleep(0)


def _ask(runtime: RobotRuntime, goal: dict[str, Any]) -> Query:
    """A move goal asked of ``runtime``, as Zenoh hands it to the queryable."""
    query = Query(f"{runtime.keys.base}/goal/move", goal)
    runtime.goals.on_move_goal(query)
    return query


async def _answered(runtime: RobotRuntime, pose: Sequence[float]) -> list[tuple[str, object]]:
    query = _ask(runtime, {"pose": list(pose)})
    await asyncio.gather(*runtime.requests.tasks)
    return [_answer(reply) for reply in query.replies]


def _answer(reply: dict[str, Any]) -> tuple[str, object]:
    if reply["accepted"]:
        return ("accepted", {"positions": reply["positions"]})
    return ("refused", reply["reason"])


@pytest.mark.parametrize("name", ["alice", "carol"])
async def test_a_pose_goal_out_of_reach_is_solved_in_slices_and_refused_naming_it(
    name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The IK of a pose out of reach (a custom robot's nine numeric starts: 2-4 ms at once) runs one
    Newton evaluation per slice, between robot cycles; the refusal is the one it always was.
    Reproduction: before, the IK ran at once inside ``goal/move``'s handler (no pose goal kind)."""
    slices = _Slices()
    monkeypatch.setattr(slicing, "sliced", slices)
    _, _, _, runtime = _parts(name)
    answers = await _answered(runtime, [5.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert answers == [
        ("refused", "move goal: pose [5.0000, 0.0000, 0.0000, 0.0000, 0.0000, 0.0000] is out of reach")
    ]
    assert slices.count >= (50 if name == "carol" else 2)
    assert runtime.motion.planning is None


async def test_a_pose_goal_is_answered_with_the_joints_nearest_ik_gives(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(slicing, "sliced", _Slices())
    cartesian, controller, backend, runtime = _parts("carol")
    kin = cartesian._kin
    start = list(backend.state.positions)
    target = [v + 0.1 for v in start]
    pose = kin.forward(target, controller.tcp)
    answers = await _answered(runtime, pose)
    expected = kin.nearest(pose, start, controller.tcp)
    assert expected is not None
    assert answers == [("accepted", {"positions": list(expected)})]
    assert controller.active_goal_id is not None  # started, to the joints it answered


async def test_a_pose_goal_being_solved_makes_goals_busy_and_a_stop_refuses_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    slices = _Slices()
    slices.hold = asyncio.Event()
    monkeypatch.setattr(slicing, "sliced", slices)
    _, controller, _, runtime = _parts("carol")
    motion = runtime.motion
    first = _ask(runtime, {"pose": [5.0, 0.0, 0.0, 0.0, 0.0, 0.0]})
    assert motion.planning == "pose move goal"
    second = _ask(runtime, {"pose": [5.0, 0.0, 0.0, 0.0, 0.0, 0.0]})
    assert [_answer(r) for r in second.replies] == [("refused", "busy: still planning pose move goal")]
    motion.end("stop requested", How.STOP)  # as a stop or a cancel does
    slices.hold.set()
    await asyncio.gather(*runtime.requests.tasks)
    assert [_answer(r) for r in first.replies] == [("refused", STOPPED_WHILE_PLANNING)]
    assert slices.count == 1  # refused at its first slice, before any IK work
    assert _planning(motion) is None
    assert controller.active_goal_id is None


def _planning(motion: RobotMotion) -> str | None:
    """What the gate says is being planned (read afresh)."""
    return motion.planning
