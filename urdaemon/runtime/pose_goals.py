"""One robot's Cartesian goals: the joint target of a pose move goal, and linear goals.

A pose move goal (``goal/move`` with ``pose``) is brought into the robot's base frame and solved by
IK on the robot's arm kinematics (the solution nearest the joints the goal starts from when it
arrives, of the named configuration if any) before it is answered: in slices between robot cycles
(the IK's ``nearest_steps`` chunks, ``sliced``), as a task under the gate (``gate.planning``: a second
goal meanwhile is refused ``busy``; stop, cancel, freedrive refuse it). It then starts exactly as a
joint move goal (runtime/goals.py ``start_move``), from the setpoint as every joint move does, so it
needs no ``gate.from_rest``; its one reply adds the joint ``positions`` chosen.

A linear goal (``goal/linear``) starts from rest only. It is decoded and its limits checked against
the cell's caps at once, then planned (control/linear.py: straight TCP lines, every cycle's joints
checked) in slices between robot cycles under the gate like a trajectory goal: a second goal while it
is planned is refused ``busy``, whatever ends motion meanwhile (stop, cancel, freedrive, ...) refuses
it, and nothing else may move the robot until it is answered (``gate.from_rest``: its plan is every
cycle's joints from where the robot rests), so it starts where it was planned from. Its reply, feedback,
result and signing are every goal's (runtime/goals.py).
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Callable, Generator, Sequence
from typing import Any

from urdaemon.backends.base import Backend
from urdaemon.cell.robot_options import CARTESIAN_PAIRS, Robot
from urdaemon.control import MotionController
from urdaemon.control.cartesian import CartesianLimits
from urdaemon.control.linear import plan_linear
from urdaemon.control.planned import ReadyPlan
from urdaemon.description.arm import ArmKinematics, base_in_world
from urdaemon.description.frames import Frame, compose, frame_of_pose, inverse, pose_of_frame
from urdaemon.errors import GoalRejected
from urdaemon.publish import linear_goal, move_goal
from urdaemon.publish.endpoints import ROBOT, Endpoint
from urdaemon.runtime.gate import STOPPED_WHILE_PLANNING, MotionGate
from urdaemon.runtime.goals import Goals
from urdaemon.runtime.queries import SHUTTING_DOWN, payload
from urdaemon.runtime.slicing import sliced

__all__ = ["Cartesian", "shown_pose"]


def shown_pose(pose: Sequence[float]) -> str:
    """A pose as a refusal shows it: ``[x, y, z, rx, ry, rz]``, four decimals."""
    return "[" + ", ".join(f"{v:.4f}" for v in pose) + "]"


class Cartesian:
    """Solves and starts one robot's pose move goals, and plans and starts its linear goals."""

    def __init__(
        self,
        robot: Robot,
        backend: Backend,
        controller: MotionController,
        goals: Goals,
        gate: MotionGate,
        kinematics: ArmKinematics | None,
        log: logging.LoggerAdapter[logging.Logger],
    ) -> None:
        self._robot = robot
        self._backend = backend
        self._controller = controller
        self._goals = goals
        self._gate = gate
        self._kin = kinematics
        self._log = log
        world = base_in_world(robot)
        self._from_world: Frame | None = None if world is None else inverse(world)
        """base -> world, to bring a world pose into base (None: the robot is not mounted on world)."""
        goals.pose_goal = self.on_pose_goal

    def endpoints(self) -> dict[Endpoint, Callable[[Any], None]]:
        """The rows of the endpoint table this part answers (the linear goal), and their handlers."""
        return {ROBOT.goal_linear: self.on_linear_goal}

    # ---- frames --------------------------------------------------------------------------------

    def _arm(self, what: str) -> ArmKinematics:
        if self._kin is None:
            raise GoalRejected(f"{what}: robot {self._robot.name} has no arm kinematics")
        return self._kin

    def in_base(self, pose: Sequence[float], frame: str, what: str) -> tuple[float, ...]:
        """``pose`` (in ``frame``: base or world) in the robot's base frame."""
        if frame == "base":
            return tuple(pose)
        if self._from_world is None:
            raise GoalRejected(
                f"{what}: frame 'world': {self._robot.name} is mounted on {self._robot.pose.parent}; "
                "its base moves with it, use frame 'base'"
            )
        return pose_of_frame(compose(self._from_world, frame_of_pose(pose)))

    # ---- pose move goals -----------------------------------------------------------------------

    def on_pose_goal(self, query: Any, goal: move_goal.MoveGoalMessage) -> None:
        """A pose move goal (decoded, free to move), solved in slices in a task (``plan_in_task``)."""
        self._goals.plan_in_task(query, "move", "pose move goal", lambda g: self._pose_goal(query, goal, g))

    async def _pose_goal(self, query: Any, goal: move_goal.MoveGoalMessage, generation: int) -> None:
        try:
            positions = await self.pose_target(goal, generation)
            self._gate.check_still_wanted(generation)  # nothing ended motion while it was solved
            goal_id, duration = self._goals.start_move(goal, positions)
        except Exception as err:  # refused, or a bug: either way the client is answered, once
            self._goals.refuse(query, "move", err)
            return
        finally:  # cancelled (shutting down): the task's done-callback answers
            self._gate.planning = None
        self._goals.accept(query, "pose move", goal_id, duration, {"positions": list(positions)})

    async def pose_target(self, goal: move_goal.MoveGoalMessage, generation: int) -> tuple[float, ...]:
        """The joints of a pose move goal, solved in slices: IK nearest the joints the goal starts
        from (of its named configuration, if any); refused naming the pose when there is none, and
        when something ends motion (``generation``) while it is solved."""
        what = "move goal"
        kin = self._arm(what)
        assert goal.pose is not None
        pose = self.in_base(goal.pose, goal.frame, what)
        start, _ = self._controller.goal_start(self._backend.state)
        tcp = self._controller.tcp
        wanted = dict(goal.configuration) if goal.configuration else None
        if wanted is None:
            found = await self._solved(kin.nearest_steps(pose, start, tcp), generation)
        elif not kin.branches:
            raise GoalRejected(
                f"{what}.configuration: robot {self._robot.name} has no named configurations (UR models only)"
            )
        else:
            steps = kin.nearest_in_steps(pose, start, tcp, wanted)  # type: ignore[attr-defined]
            found = await self._solved(steps, generation)
        if found is not None:
            return tuple(found)
        shown = shown_pose(goal.pose)
        if wanted and await self._solved(kin.nearest_steps(pose, start, tcp), generation) is not None:
            named = ", ".join(f"{group}={value}" for group, value in goal.configuration)
            raise GoalRejected(f"{what}: pose {shown} has no solution with configuration {named}")
        raise GoalRejected(f"{what}: pose {shown} is out of reach")

    async def _solved(
        self, steps: Generator[None, None, Sequence[float] | None], generation: int
    ) -> Sequence[float] | None:
        """Run an IK's chunks (``nearest_steps``) in slices between robot cycles; what it returns.
        Refused (``GoalRejected``) at the next slice once something ends motion or the daemon closes."""
        gate = self._gate
        answer: list[Sequence[float] | None] = []

        def step(deadline: float) -> bool:
            if gate.generation != generation or gate.closing:  # stop, cancel, freedrive: no more work
                raise GoalRejected(SHUTTING_DOWN if gate.closing else STOPPED_WHILE_PLANNING)
            try:
                while True:
                    next(steps)  # one chunk: a Newton evaluation, 10-60 µs
                    if time.perf_counter() > deadline:
                        return True
            except StopIteration as stop:
                answer.append(stop.value)
                return False

        try:
            await sliced(step)
        finally:
            steps.close()
        return answer[0]

    # ---- linear goals --------------------------------------------------------------------------

    def limits(self, goal: linear_goal.LinearGoalMessage) -> CartesianLimits:
        """The goal's Cartesian limits: those it names (each at most the cell's cap), the cell's
        defaults for the rest."""
        options = self._robot.motion.cartesian
        named = dict(goal.limits)
        values = []
        for name, cap, unit in CARTESIAN_PAIRS:
            value = named.get(name)
            if value is None:
                value = getattr(options, name)
            elif value > getattr(options, cap):
                raise GoalRejected(
                    f"linear goal.{name}: {value:g} {unit} is above the cap {cap} {getattr(options, cap):g} "
                    f"{unit} (the cell file's motion.cartesian)"
                )
            values.append(value)
        return CartesianLimits(*values)

    def on_linear_goal(self, query: Any) -> None:
        """A linear goal, planned in slices in a task (``plan_in_task``)."""
        self._goals.plan_in_task(
            query, "linear", "linear goal being decoded", lambda g: self._linear_goal(query, g)
        )

    async def _linear_goal(self, query: Any, generation: int) -> None:
        try:
            decoder = linear_goal.LinearGoalDecoder(payload(query))
            await sliced(lambda deadline: decoder.step(deadline, time.perf_counter))
            goal = decoder.result()
            plan = await self._plan(goal, generation)
            self._gate.check_still_wanted(generation)  # nothing ended motion while it was planned
            tolerances = self._goals.tolerances(goal.tolerances, self._controller.joint_names)
            goal_id, duration = self._goals.start_ready(plan, tolerances)
        except Exception as err:  # refused, or a bug: either way the client is answered, once
            self._goals.refuse(query, "linear", err)
            return
        finally:  # cancelled (shutting down): the task's done-callback answers
            self._gate.planning = None
        self._goals.accept(query, "linear", goal_id, duration)

    async def _plan(self, goal: linear_goal.LinearGoalMessage, generation: int) -> ReadyPlan:
        """Check and plan a linear goal from where the robot rests, in slices between robot cycles."""
        what = "linear goal"
        kin = self._arm(what)
        limits = self.limits(goal)
        poses = [self.in_base(pose, goal.frame, what) for pose in goal.poses]
        gate, controller = self._gate, self._controller
        gate.check_still_wanted(generation)
        state = self._backend.state
        controller.check_can_start(state, time.monotonic(), False)
        start, at_rest = controller.goal_start(state)
        if not at_rest:
            raise GoalRejected(f"{what}: the robot is moving; a linear goal starts from rest")
        gate.planning = f"linear goal of {len(poses)} pose{'s' if len(poses) != 1 else ''}"
        check = plan_linear(
            kin,
            start,
            poses,
            goal.blend_radii,
            controller.tcp,
            limits,
            controller.plan_limits,
            self._backend.period,
        )

        def step(deadline: float) -> bool:
            if gate.generation != generation or gate.closing:  # stop, cancel, freedrive: no more work
                raise GoalRejected(SHUTTING_DOWN if gate.closing else STOPPED_WHILE_PLANNING)
            while check.step(1):  # one chunk of an IK (a Newton evaluation) or one sample's checks
                if time.perf_counter() > deadline:
                    return True
            return False

        gate.from_rest = True  # nothing else may move the robot until this goal is answered
        try:
            await sliced(step)
            return check.result()
        finally:
            gate.from_rest = False
            with contextlib.suppress(Exception):
                check.close()
