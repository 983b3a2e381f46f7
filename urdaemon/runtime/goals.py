"""One robot's goals: trajectory, move (to joints or a TCP pose) and linear goals, cancel, and their
replies.

Every kind of goal that is planned before it is answered is one row of ``GOAL_KINDS``: refused at
once while shutting down or while another goal is planned (runtime/motion.py ``claim``), then
decoded, checked and planned in slices between robot cycles under the gate (``RobotMotion.plan``) in
a task that answers its query once, and started only if nothing ended motion meanwhile. A trajectory
goal's pipeline also plans each robot's part of a cell goal (runtime/cell_goals.py). A move goal to
joint positions is decided at once. Every accepted goal ends with exactly one result, published and
kept to answer late queries (runtime/goal_events.py).

A pose move goal (``goal/move`` with ``pose``) is solved by IK in slices (runtime/pose_goals.py), then
starts exactly as a joint move goal, from the setpoint, so it needs no "from rest"; its one reply adds
the joint ``positions`` chosen. A linear goal (``goal/linear``) starts from rest only: it is planned
"from rest" (nothing else may move the robot until it is answered), so it starts where it was planned
from.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import time
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

from urdaemon.backends.base import Backend
from urdaemon.cell.robot_options import Robot
from urdaemon.control import MotionController, Tolerances
from urdaemon.control.trajectory import TrajectoryPlanner
from urdaemon.errors import GoalRejected, MessageError, UrDaemonError
from urdaemon.publish import goal_cancel, linear_goal, move_goal
from urdaemon.publish.endpoints import ROBOT, Endpoint
from urdaemon.publish.fields import ToleranceMessage
from urdaemon.publish.keys import RobotKeys
from urdaemon.publish.move_goal import MoveGoalMessage
from urdaemon.publish.node import ZenohNode
from urdaemon.publish.trajectory_json import TrajectoryGoalDecoder
from urdaemon.runtime.goal_events import GoalEvents
from urdaemon.runtime.motion import How, RobotMotion, Ticket
from urdaemon.runtime.passthrough import Passthrough
from urdaemon.runtime.pose_goals import Cartesian
from urdaemon.runtime.queries import SHUTTING_DOWN, Requests, internal_error, payload, reply
from urdaemon.runtime.slicing import release

__all__ = ["GOAL_KINDS", "GoalKind", "Goals", "PlannedGoal", "Started"]


@dataclass(slots=True)
class PlannedGoal:
    """A trajectory goal decoded, checked and planned (for passthrough encoded), not started yet."""

    preempt: bool
    passthrough: bool
    tolerances: Tolerances | None
    planner: TrajectoryPlanner
    frames: tuple[bytes, int] | None
    """The points as the robot receives them (passthrough only), and how many."""


class Started(NamedTuple):
    """A goal that started: what its log line calls it, its id and duration, what its reply adds."""

    kind: str
    goal_id: str
    duration: float
    extra: dict[str, Any] | None = None


Planning = Callable[["Goals", Any, Any, Ticket, list[object]], Coroutine[Any, Any, Started]]
"""A kind's planning: ``(goals, query, message, ticket, owned)`` (``message``: the request decoded at
once, if it was), answered by what started."""


@dataclass(frozen=True, slots=True)
class GoalKind:
    """A kind of goal planned before it is answered."""

    refused: str
    """What a refusal's log line calls it."""
    planning: str
    """What the gate says is planned until the goal says more (kind first: it goes in replies)."""
    plan: Planning


class Goals:
    """Accepts, plans, starts and cancels one robot's goals."""

    def __init__(
        self,
        *,
        robot: Robot,
        backend: Backend,
        controller: MotionController,
        node: ZenohNode,
        keys: RobotKeys,
        motion: RobotMotion,
        events: GoalEvents,
        requests: Requests,
        cartesian: Cartesian | None,
        log: logging.LoggerAdapter[logging.Logger],
    ) -> None:
        self._robot = robot
        self._backend = backend
        self._controller = controller
        self._node = node
        self._keys = keys
        self._motion = motion
        self.events = events
        self._requests = requests
        self._cartesian = cartesian
        """Pose move and linear goals' IK and plans (None: the robot has no arm kinematics)."""
        self._log = log
        self.passthrough = Passthrough(backend, controller, log)

    def endpoints(self) -> dict[Endpoint, Callable[[Any], None]]:
        """The rows of the endpoint table this part answers, and their handlers (robot.py declares
        them: publish/endpoints.py says each one's key, size limit, reply field and lease)."""
        return {
            ROBOT.goal_trajectory: self.on_trajectory_goal,
            ROBOT.goal_move: self.on_move_goal,
            ROBOT.goal_linear: self.on_linear_goal,
            ROBOT.goal_cancel: self.on_cancel,
            ROBOT.goal_results: self.on_result_query,
        }

    def on_result_query(self, query: Any) -> None:
        """Answer a query for a finished goal's result (runtime/goal_events.py)."""
        self.events.answer_result_query(query)

    # ---- shared by every kind of goal ------------------------------------------------------------

    def joint_names(self, names: Sequence[str] | None) -> tuple[str, ...]:
        """Client joint names → controller names; names may leave out the robot prefix."""
        own = self._controller.joint_names
        if names is None:
            return own
        known = set(own)
        prefix = self._robot.prefix
        return tuple(n if n in known or f"{prefix}{n}" not in known else f"{prefix}{n}" for n in names)

    def tolerances(self, message: ToleranceMessage, names: tuple[str, ...]) -> Tolerances | None:
        """A goal's tolerances in the controller's joint order (None: the robot's defaults)."""
        if message.path is None and message.goal is None and message.goal_time is None:
            return None
        own = self._controller.joint_names

        def per_joint(value: float | tuple[float, ...] | None, label: str) -> tuple[float, ...] | None:
            if value is None:
                return None
            if isinstance(value, float):
                return (value,) * len(own)
            if len(value) != len(names):
                raise GoalRejected(f"tolerances.{label} has {len(value)} values for {len(names)} joints")
            by_name = dict(zip(names, value, strict=True))
            missing = [n for n in own if n not in by_name]
            if missing:
                raise GoalRejected(f"tolerances.{label}: no value for joint(s) {', '.join(missing)}")
            return tuple(by_name[n] for n in own)

        return Tolerances(
            path=per_joint(message.path, "path"),
            goal=per_joint(message.goal, "goal"),
            goal_time=message.goal_time,
        )

    def accept(self, query: Any, started: Started) -> None:
        """Answer a goal that started (``extra``: what its reply adds), then log and publish it."""
        key = self.events.result_key(started.goal_id)
        body = {"accepted": True, "goal_id": started.goal_id, "duration": started.duration, "result_key": key}
        reply(query, body if started.extra is None else {**body, **started.extra})
        self.started(started.kind, started.goal_id, started.duration)

    def started(self, kind: str, goal_id: str, duration: float) -> None:
        """Log a goal just started, publish what it ended (a preempted goal's result goes out before
        the new goal's feedback) and the status."""
        self._log.info("%s goal %s accepted (%.3f s)", kind, goal_id, duration)
        self._motion.report()

    def refuse(self, query: Any, kind: str, err: Exception) -> None:
        """Answer a goal that did not start: rejected (a bad message, a refusal: logged as a warning)
        or failed on a bug (logged with its traceback: call this from the except block)."""
        if isinstance(err, (MessageError, GoalRejected)):
            self._reject(query, kind, err)
        else:
            self._log.exception("%s goal failed", kind)
            reply(query, {"accepted": False, "reason": internal_error(err)})

    def _reject(self, query: Any, kind: str, err: UrDaemonError) -> None:
        reason = err.reason if isinstance(err, GoalRejected) else str(err)
        self._log.warning("%s goal rejected: %s", kind, reason)
        reply(query, {"accepted": False, "reason": reason})

    # ---- goals planned before they are answered (GOAL_KINDS) -------------------------------------

    def on_trajectory_goal(self, query: Any) -> None:
        """A trajectory goal, planned in a task."""
        self._take(query, GOAL_KINDS["trajectory"])

    def on_linear_goal(self, query: Any) -> None:
        """A linear goal, planned in a task."""
        self._take(query, GOAL_KINDS["linear"])

    def _take(self, query: Any, kind: GoalKind, message: Any = None) -> None:
        """Refused at once while shutting down or while another goal is planned (before reading a byte
        of it), else planned in a task that answers ``query`` once. What ended motion before this
        query counts as before it."""
        try:
            ticket = self._motion.claim(kind.planning)
        except GoalRejected as err:
            self.refuse(query, kind.refused, err)
            return
        work = self._planned(query, message, kind, ticket)
        self._requests.spawn(work, query, {"accepted": False, "reason": SHUTTING_DOWN})

    async def _planned(self, query: Any, message: Any, kind: GoalKind, ticket: Ticket) -> None:
        """Plan and start a goal, answer it, then free what it decoded and planned in slices too (a
        5 000-point goal's points take ~1 ms to free at once)."""
        owned: list[object] = []
        try:
            with ticket:  # cancelled (shutting down): the task's done-callback answers
                started = await kind.plan(self, query, message, ticket, owned)
        except Exception as err:  # refused, or a bug: either way the client is answered, once
            self.refuse(query, kind.refused, err)
        else:
            self.accept(query, started)
        if owned:
            with contextlib.suppress(asyncio.CancelledError):  # answered already: shutting down frees it
                await release(owned)

    async def _trajectory_goal(self, query: Any, _: None, ticket: Ticket, owned: list[object]) -> Started:
        planned = await self.plan_trajectory(ticket, payload(query), owned)
        self.check_startable(planned, ticket.generation)  # nothing ended motion while it was planned
        goal_id, duration = self.start_planned(planned)
        return Started("passthrough trajectory" if planned.passthrough else "trajectory", goal_id, duration)

    async def plan_trajectory(
        self,
        ticket: Ticket,
        body: bytes | memoryview | None,
        owned: list[object],
        *,
        no_passthrough: str | None = None,
    ) -> PlannedGoal:
        """Decode, check and plan a trajectory goal's ``body`` (for passthrough encode it too), all in
        slices between robot cycles under ``ticket``; what it decoded and planned goes into ``owned``
        (to be freed in slices). Raises ``MessageError`` or ``GoalRejected`` (``no_passthrough``: the
        reason a passthrough goal is refused here)."""
        motion, controller = self._motion, self._controller
        goal = await motion.plan(ticket, TrajectoryGoalDecoder(body).steps())
        owned.append(goal.points)  # decoded here: nobody else holds the list
        if goal.passthrough and no_passthrough is not None:
            raise GoalRejected(no_passthrough)
        names = self.joint_names(goal.joint_names)
        tolerances = self.tolerances(goal.tolerances, names)
        motion.check_still_wanted(ticket.generation)
        if goal.passthrough:
            self.passthrough.check_available()
        controller.check_can_start(self._backend.state, time.monotonic(), goal.preempt)
        what = f"trajectory of {len(goal.points)} points"
        check = controller.check_trajectory(names, goal.points, self._backend.state)
        planner = await motion.plan(ticket, check, what=what)
        owned.append(planner)  # the controller keeps the plan it finishes, never the planner
        await motion.plan(ticket, planner.tail_steps())
        frames = None
        if goal.passthrough:
            frames = await motion.plan(ticket, self.passthrough.encode_steps(planner))
        return PlannedGoal(goal.preempt, goal.passthrough, tolerances, planner, frames)

    def check_startable(self, planned: PlannedGoal, generation: int) -> None:
        """Refuse (``GoalRejected``) a planned goal that could not start now: shutting down, something
        ended motion since ``generation``, not ready, busy."""
        self._motion.check_still_wanted(generation)
        self._motion.check_not_planning_from_rest()  # a cell goal's part while a linear goal is planned
        if planned.passthrough:
            self.passthrough.check_available()
        self._controller.check_can_start(self._backend.state, time.monotonic(), planned.preempt)

    def start_planned(self, planned: PlannedGoal) -> tuple[str, float]:
        """Start a planned goal now (on the robot's next cycle); its id and planned duration."""
        goal_id = self.events.new_goal()
        try:
            if planned.frames is not None:
                duration = self.passthrough.start(
                    goal_id, planned.planner, planned.tolerances, planned.frames, self._on_passthrough_result
                )
            else:
                duration = self._controller.accept_trajectory(
                    goal_id,
                    self._controller.joint_names,  # the planner's points are in the controller's order
                    planned.planner.points,
                    self._backend.state,
                    time.monotonic(),
                    tolerances=planned.tolerances,
                    preempt=planned.preempt,
                    planner=planned.planner,
                )
        except BaseException:
            self.events.forget(goal_id)
            raise
        return goal_id, duration

    def _on_passthrough_result(self, goal_id: str, code: int, why: str | None) -> None:
        if self.passthrough.finish(goal_id, code, why):
            self._motion.report()

    async def _pose_goal(self, query: Any, goal: MoveGoalMessage, ticket: Ticket, _: list[object]) -> Started:
        positions = await self._motion.plan(ticket, self._arm().pose_steps(goal))
        self._motion.check_still_wanted(ticket.generation)  # nothing ended motion while it was solved
        goal_id, duration = self.start_move(goal, positions)
        return Started("pose move", goal_id, duration, {"positions": list(positions)})

    async def _linear_goal(self, query: Any, _: None, ticket: Ticket, owned: list[object]) -> Started:
        motion = self._motion
        goal = await motion.plan(ticket, linear_goal.LinearGoalDecoder(payload(query)).steps())
        cartesian = self._arm()
        limits, poses = cartesian.linear_targets(goal)
        motion.check_still_wanted(ticket.generation)
        steps = cartesian.linear_steps(goal, limits, poses)
        what = f"linear goal of {len(poses)} pose{'s' if len(poses) != 1 else ''}"
        plan = await motion.plan(ticket, steps, what=what, from_rest=True)
        motion.check_still_wanted(ticket.generation)  # nothing ended motion while it was planned
        tolerances = self.tolerances(goal.tolerances, self._controller.joint_names)
        goal_id = self.events.new_goal()
        try:
            state = self._backend.state
            duration = self._controller.accept_planned(
                goal_id, plan, state, time.monotonic(), tolerances=tolerances
            )
        except BaseException:
            self.events.forget(goal_id)  # never started: no result will use it
            raise
        return Started("linear", goal_id, duration)

    def _arm(self) -> Cartesian:
        if self._cartesian is None:
            raise GoalRejected(f"linear goal: robot {self._robot.name} has no arm kinematics")
        return self._cartesian

    # ---- move goals ------------------------------------------------------------------------------

    def on_move_goal(self, query: Any) -> None:
        """A point-to-point move goal to joint positions, decided at once; one to a TCP pose is planned
        in a task (``GOAL_KINDS["pose"]``: its IK is solved in slices)."""
        try:
            if self._motion.closing:
                raise GoalRejected(SHUTTING_DOWN)
            goal = move_goal.decode_move_goal(payload(query))
            self._motion.check_free_to_move()
            self._motion.check_not_planning_from_rest()
            if goal.pose is not None:
                if self._cartesian is None:
                    raise GoalRejected(f"move goal.pose: robot {self._robot.name} has no arm kinematics")
                self._take(query, GOAL_KINDS["pose"], goal)
                return
            goal_id, duration = self.start_move(goal)
        except Exception as err:  # refused, or a bug: either way the client is answered, once
            self.refuse(query, "move", err)
            return
        self.accept(query, Started("move", goal_id, duration))

    def start_move(
        self, goal: MoveGoalMessage, positions: Sequence[float] | None = None
    ) -> tuple[str, float]:
        """Start a move goal now, to its ``positions`` (a pose goal's: the IK's ``positions``); its id
        and duration. Raises ``GoalRejected``."""
        if positions is not None:
            goal = dataclasses.replace(goal, positions=tuple(positions))
        names = self.joint_names(goal.joint_names)
        tolerances = self.tolerances(goal.tolerances, names)
        goal_id = self.events.new_goal()
        try:
            return goal_id, self._controller.accept_move(
                goal_id,
                names,
                goal.positions,
                self._backend.state,
                time.monotonic(),
                duration=goal.duration,
                velocity_scale=goal.velocity_scale,
                acceleration_scale=goal.acceleration_scale,
                tolerances=tolerances,
                preempt=goal.preempt,
            )
        except BaseException:
            self.events.forget(goal_id)  # never started: no result will use it
            raise

    # ---- what ends goals (runtime/motion.py ``end``) ---------------------------------------------

    def stop_goal(self, goal_id: str, reason: str) -> bool:
        """Stop the goal ``goal_id`` if it runs (it ends ``aborted`` with ``reason``); False if not."""
        return self._motion.end(reason, How.STOP, goal_id).ended

    def cancel_goal(self, goal_id: str) -> bool:
        """Cancel the goal ``goal_id`` if it runs (it ends ``canceled``); False if not."""
        return self._motion.end("canceled", How.CANCEL, goal_id).ended

    def on_cancel(self, query: Any) -> None:
        """Cancel a goal (default: the active one, and a goal being planned)."""
        try:
            goal_id = goal_cancel.decode_cancel(payload(query))
        except MessageError as err:
            reply(query, {"canceled": False, "reason": str(err)})
            return
        target = goal_id if goal_id is not None else self._controller.active_goal_id
        # a goal being planned has no id yet: a cancel of no id, or of nothing active, cancels it
        ended = self._motion.end("canceled", How.CANCEL, goal_id, or_planned=True)
        body: dict[str, Any] = {"canceled": ended.ended, "goal_id": target}
        if ended.planned is not None:
            body["canceled"] = True
            body["planned"] = ended.planned
        elif not ended.ended:
            body["reason"] = "no active goal" if target is None else f"goal {target} is not active"
        reply(query, body)


GOAL_KINDS: dict[str, GoalKind] = {
    "trajectory": GoalKind("trajectory", "trajectory being decoded", Goals._trajectory_goal),
    "pose": GoalKind("move", "pose move goal", Goals._pose_goal),
    "linear": GoalKind("linear", "linear goal being decoded", Goals._linear_goal),
}
"""The goals planned before they are answered, by kind: what a refusal calls it, what the gate says
while it is decoded (or solved), and its planning. A cell goal's part is planned by the trajectory's
(``plan_trajectory``, under the cell goal's ticket); a move goal to joints is decided at once."""
