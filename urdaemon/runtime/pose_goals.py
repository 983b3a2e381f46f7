"""One robot's Cartesian goals worked out: the joint target of a pose move goal, and a linear goal's plan.

A pose move goal (``goal/move`` with ``pose``) is brought into the robot's base frame and solved by
IK on the robot's arm kinematics (the solution nearest the joints the goal starts from when it
arrives, of the named configuration if any): in steps (the IK's ``nearest_steps`` chunks), which
runtime/goals.py runs in slices under the gate (runtime/motion.py ``plan``).

A linear goal (``goal/linear``) starts from rest only: its limits are checked against the cell's
caps, its poses brought into the base frame, then it is planned (control/linear.py: straight TCP
lines, every cycle's joints checked) in steps from where the robot rests, which runtime/goals.py
runs in slices "from rest".
"""

from __future__ import annotations

import logging
import time
from collections.abc import Generator, Sequence

from urdaemon.backends.base import Backend
from urdaemon.cell.robot_options import CARTESIAN_PAIRS, Robot
from urdaemon.control import MotionController
from urdaemon.control.cartesian import CartesianLimits
from urdaemon.control.linear import plan_linear
from urdaemon.control.sampled import SampledTrajectory
from urdaemon.description.arm import ArmKinematics, base_in_world
from urdaemon.description.frames import Frame, compose, frame_of_pose, inverse, pose_of_frame
from urdaemon.errors import GoalRejected
from urdaemon.publish import linear_goal, move_goal

__all__ = ["Cartesian", "shown_pose"]


def shown_pose(pose: Sequence[float]) -> str:
    """A pose as a refusal shows it: ``[x, y, z, rx, ry, rz]``, four decimals."""
    return "[" + ", ".join(f"{v:.4f}" for v in pose) + "]"


class Cartesian:
    """Works out one robot's pose move goals' joints and its linear goals' plans, in steps."""

    def __init__(
        self,
        *,
        robot: Robot,
        backend: Backend,
        controller: MotionController,
        kinematics: ArmKinematics,
        log: logging.LoggerAdapter[logging.Logger],
    ) -> None:
        self._robot = robot
        self._backend = backend
        self._controller = controller
        self._kin = kinematics
        self._log = log
        world = base_in_world(robot)
        self._from_world: Frame | None = None if world is None else inverse(world)
        """base -> world, to bring a world pose into base (None: the robot is not mounted on world)."""

    # ---- frames --------------------------------------------------------------------------------

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

    def pose_steps(self, goal: move_goal.MoveGoalMessage) -> Generator[None, None, tuple[float, ...]]:
        """The joints of a pose move goal, in steps: IK nearest the joints the goal starts from (of
        its named configuration, if any); refused naming the pose when there is none."""
        what = "move goal"
        kin = self._kin
        assert goal.pose is not None
        pose = self.in_base(goal.pose, goal.frame, what)
        start, _ = self._controller.goal_start(self._backend.state)
        tcp = self._controller.tcp
        wanted = dict(goal.configuration) if goal.configuration else None
        if wanted is None:
            found = yield from kin.nearest_steps(pose, start, tcp)
        elif not kin.branches:
            raise GoalRejected(
                f"{what}.configuration: robot {self._robot.name} has no named configurations (UR models only)"
            )
        else:
            found = yield from kin.nearest_in_steps(pose, start, tcp, wanted)  # type: ignore[attr-defined]
        if found is not None:
            return tuple(found)
        shown = shown_pose(goal.pose)
        if wanted and (yield from kin.nearest_steps(pose, start, tcp)) is not None:
            named = ", ".join(f"{group}={value}" for group, value in goal.configuration)
            raise GoalRejected(f"{what}: pose {shown} has no solution with configuration {named}")
        raise GoalRejected(f"{what}: pose {shown} is out of reach")

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

    def linear_targets(
        self, goal: linear_goal.LinearGoalMessage
    ) -> tuple[CartesianLimits, list[tuple[float, ...]]]:
        """A linear goal's limits (``limits``) and its poses in the base frame; refused naming why."""
        return self.limits(goal), [self.in_base(pose, goal.frame, "linear goal") for pose in goal.poses]

    def linear_steps(
        self, goal: linear_goal.LinearGoalMessage, limits: CartesianLimits, poses: list[tuple[float, ...]]
    ) -> Generator[None, None, SampledTrajectory]:
        """A linear goal planned from where the robot rests, in steps; refused at once if it could not
        start now or the robot moves."""
        controller = self._controller
        state = self._backend.state
        controller.check_can_start(state, time.monotonic(), False)
        start, at_rest = controller.goal_start(state)
        if not at_rest:
            raise GoalRejected("linear goal: the robot is moving; a linear goal starts from rest")
        return plan_linear(
            self._kin,
            start,
            poses,
            goal.blend_radii,
            controller.tcp,
            limits,
            controller.plan_limits,
            self._backend.period,
        )
