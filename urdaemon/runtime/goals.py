"""One robot's goals: trajectory and move goals, cancel, and their feedback and results.

A trajectory goal is decoded, checked, planned (and for passthrough encoded) in slices between
robot cycles, then started; it is accepted only if nothing ended motion meanwhile (gate.py). The
same pipeline plans each robot's part of a cell goal (runtime/cell_goals.py). Every accepted goal
ends with exactly one result, published and kept to answer late queries.

Every goal gets a key of its own (publish/signing.py) when it starts: the accepting reply gives it
to the client, and every feedback and result message of the goal (and every answer to a query for
its result) carries, as its Zenoh attachment, the signature of the message together with the key
it is published on (so a feedback cannot pass for a result). The signature is made when a message
is published, at the feedback rate (10 Hz by default) and once per result, never once per cycle; a
kept result keeps its signature, not the key.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import itertools
import logging
import secrets
import time
from collections import OrderedDict
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import dataclass
from typing import Any

import zenoh

from urdaemon.backends.base import Backend
from urdaemon.cell.robot_options import Robot
from urdaemon.control import GoalFeedback, GoalResult, MotionController, Tolerances
from urdaemon.control.planned import ReadyPlan
from urdaemon.control.trajectory import TrajectoryPlanner
from urdaemon.errors import GoalRejected, MessageError, UrDaemonError
from urdaemon.publish import envelope, goal_cancel, move_goal, signing
from urdaemon.publish.endpoints import ROBOT, Endpoint
from urdaemon.publish.fields import ToleranceMessage
from urdaemon.publish.keys import RobotKeys
from urdaemon.publish.move_goal import MoveGoalMessage
from urdaemon.publish.node import ZenohNode
from urdaemon.publish.trajectory_json import TrajectoryGoalDecoder
from urdaemon.runtime.gate import MotionGate
from urdaemon.runtime.passthrough import Passthrough
from urdaemon.runtime.queries import SHUTTING_DOWN, Requests, internal_error, payload, reply
from urdaemon.runtime.slicing import check_sliced, decode_sliced, plan_tail, release
from urdaemon.runtime.status import StatusPublisher

__all__ = ["KEPT_RESULTS", "Goals", "PlannedGoal", "PoseGoal", "ResultListener", "put_signed"]

KEPT_RESULTS = 256
"""Finished goal results kept to answer late queries (each with its signature)."""

PoseGoal = Callable[[Any, MoveGoalMessage], None]
"""Takes a decoded pose move goal and its query: solves its IK in slices, then starts it as a joint
move goal (``start_move``) or refuses it, answering the query once (runtime/pose_goals.py)."""

ResultListener = Callable[[GoalResult, bytes], None]
"""Told a goal's result (and its message as published) once it is published: a cell goal's part."""


def _stamp(backend: Backend) -> dict[str, Any]:
    """The time fields of a goal message: the newest state's (the cycle's, in a cycle)."""
    return envelope.state_time(backend.state, time.time_ns())


def put_signed(node: ZenohNode, key: str, payload: bytes, attachment: bytes) -> None:
    """Publish once on ``key`` with ``attachment`` (a goal message's signature), dropped rather than
    blocking when congested (``ZenohNode.put``)."""
    with contextlib.suppress(zenoh.ZError):  # the session closed: nobody is left to hear it
        node.put(key, payload, attachment=attachment)


@dataclass(slots=True)
class PlannedGoal:
    """A trajectory goal decoded, checked and planned (for passthrough encoded), not started yet."""

    preempt: bool
    passthrough: bool
    tolerances: Tolerances | None
    planner: TrajectoryPlanner
    frames: tuple[bytes, int] | None
    """The points as the robot receives them (passthrough only), and how many."""


class Goals:
    """Accepts, cancels and reports one robot's goals."""

    def __init__(
        self,
        robot: Robot,
        backend: Backend,
        controller: MotionController,
        node: ZenohNode,
        keys: RobotKeys,
        parts: tuple[MotionGate, Requests, StatusPublisher],
        log: logging.LoggerAdapter[logging.Logger],
    ) -> None:
        self._robot = robot
        self._backend = backend
        self._controller = controller
        self._keys = keys
        self._gate, self._requests, self._status = parts
        self._log = log
        self._node = node
        self.passthrough = Passthrough(backend, controller, log)
        self._results: OrderedDict[str, tuple[bytes, bytes]] = OrderedDict()
        """Finished goals' result messages and their signatures, oldest first."""
        self._keys_of: dict[str, str] = {}
        """Each running goal's signing key (until its result is published)."""
        self.result_listeners: dict[str, ResultListener] = {}
        """Who is told a goal's result when it is published, by goal id (told once, then forgotten)."""
        self._ids = itertools.count(1)
        self._salt = secrets.token_hex(2)
        self.pose_goal: PoseGoal | None = None
        """Handles pose move goals (IK in slices: runtime/pose_goals.py); None: no arm kinematics."""

    def endpoints(self) -> dict[Endpoint, Callable[[Any], None]]:
        """The rows of the endpoint table this part answers, and their handlers (robot.py declares
        them: publish/endpoints.py says each one's key, size limit, reply field and lease)."""
        return {
            ROBOT.goal_trajectory: self.on_trajectory_goal,
            ROBOT.goal_move: self.on_move_goal,
            ROBOT.goal_cancel: self.on_cancel,
            ROBOT.goal_results: self.on_result_query,
        }

    # ---- events and results ----------------------------------------------------------------------

    def publish_events(self) -> None:
        """Publish the controller's goal feedback and results, each signed with its goal's key."""
        for event in self._controller.drain_events():
            if isinstance(event, GoalResult):
                self.passthrough.ended_here(event.goal_id)
            if isinstance(event, GoalFeedback):
                message = envelope.encode_feedback(self._robot.name, event, _stamp(self._backend))
                key = self._keys_of.get(event.goal_id)
                if key is not None:  # at the feedback rate, never once per cycle
                    on = self._keys.goal_feedback(event.goal_id)
                    put_signed(self._node, on, message, signing.sign(key, on, message))
            else:
                self._publish_result(event)

    def _publish_result(self, result: GoalResult) -> None:
        message = envelope.encode_result(self._robot.name, result, _stamp(self._backend))
        key = self._keys_of.pop(result.goal_id, None) or signing.new_key()  # every goal has one
        on = self._keys.goal_result(result.goal_id)  # signed with the key it goes out on
        signature = signing.sign(key, on, message)
        self._results[result.goal_id] = (message, signature)
        while len(self._results) > KEPT_RESULTS:
            self._results.popitem(last=False)
        put_signed(self._node, on, message, signature)
        log = self._log.info if result.status.value == "succeeded" else self._log.warning
        log(
            "goal %s %s%s", result.goal_id, result.status.value, f": {result.reason}" if result.reason else ""
        )
        listener = self.result_listeners.pop(result.goal_id, None)
        if listener is not None:
            listener(result, message)

    def on_result_query(self, query: Any) -> None:
        """Answer a query for a finished goal's result, signed (nothing while it runs or once forgotten)."""
        goal_id = self._keys.goal_of_result(str(query.key_expr))
        kept = self._results.get(goal_id) if goal_id is not None else None
        if goal_id is not None and kept is not None:
            with contextlib.suppress(Exception):  # the querier may have timed out and gone
                query.reply(self._keys.goal_result(goal_id), kept[0], attachment=kept[1])
        with contextlib.suppress(Exception):
            query.drop()

    # ---- shared by both kinds of goal ------------------------------------------------------------

    def _new_goal(self) -> tuple[str, str]:
        """A new goal's id and signing key (kept until its result is published)."""
        goal_id = f"{self._robot.name}-{self._salt}-{next(self._ids)}"
        key = self._keys_of[goal_id] = signing.new_key()
        return goal_id, key

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

    def accept(
        self, query: Any, kind: str, goal_id: str, duration: float, extra: dict[str, Any] | None = None
    ) -> None:
        """Answer a goal that started (``extra``: what its reply adds), then log and publish it."""
        key = self._keys_of.get(goal_id)
        body = {"accepted": True, "goal_id": goal_id, "duration": duration, "result_key": key}
        reply(query, body if extra is None else {**body, **extra})
        self.started(kind, goal_id, duration)

    def started(self, kind: str, goal_id: str, duration: float) -> None:
        """Log a goal just started, publish what it ended (a preempted goal's result goes out before
        the new goal's feedback) and the status."""
        self._log.info("%s goal %s accepted (%.3f s)", kind, goal_id, duration)
        self.publish_events()
        self._status.publish()

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

    # ---- trajectory goals ------------------------------------------------------------------------

    def plan_in_task(
        self, query: Any, kind: str, planning: str, work: Callable[[int], Coroutine[Any, Any, None]]
    ) -> None:
        """A goal planned in slices: refused at once while shutting down or while another goal is
        planned (before reading a byte of it), else ``gate.planning`` says ``planning`` and
        ``work(generation)`` runs in a task that answers ``query`` once and clears it. The generation
        is recorded now: what ended motion before this query counts as before it."""
        gate = self._gate
        if gate.closing:
            self.refuse(query, kind, GoalRejected(SHUTTING_DOWN))
            return
        if gate.planning is not None:
            self.refuse(query, kind, GoalRejected(f"busy: still planning {gate.planning}"))
            return
        gate.planning = planning
        self._requests.spawn(work(gate.generation), query, {"accepted": False, "reason": SHUTTING_DOWN})

    def on_trajectory_goal(self, query: Any) -> None:
        """A trajectory goal, planned in a task (``plan_in_task``)."""
        self.plan_in_task(
            query, "trajectory", "trajectory being decoded", lambda g: self._trajectory_goal(query, g)
        )

    async def _trajectory_goal(self, query: Any, generation: int) -> None:
        """Decode, check, plan (and for passthrough encode) a trajectory goal, all in slices between
        robot cycles, then start it; then free what it decoded and planned in slices too (a 5 000-point
        goal's points take ~1 ms to free at once)."""
        owned: list[object] = []
        await self._handle_trajectory_goal(query, generation, owned)
        with contextlib.suppress(asyncio.CancelledError):  # answered already: shutting down frees it
            await release(owned)

    async def _handle_trajectory_goal(self, query: Any, generation: int, owned: list[object]) -> None:
        try:
            planned = await self.plan_trajectory(payload(query), generation, owned)
            self.check_startable(planned, generation)  # nothing ended motion while it was planned
            goal_id, duration = self.start_planned(planned)
        except Exception as err:  # refused, or a bug: either way the client is answered, once
            self.refuse(query, "trajectory", err)
            return
        finally:  # cancelled (shutting down): the task's done-callback answers
            self._gate.planning = None
        self.accept(
            query, "passthrough trajectory" if planned.passthrough else "trajectory", goal_id, duration
        )

    async def plan_trajectory(
        self,
        body: bytes | memoryview | None,
        generation: int,
        owned: list[object],
        *,
        no_passthrough: str | None = None,
    ) -> PlannedGoal:
        """Decode, check and plan a trajectory goal's ``body`` (for passthrough encode it too), all in
        slices between robot cycles; what it decoded and planned goes into ``owned`` (to be freed in
        slices). Raises ``MessageError`` or ``GoalRejected`` (``no_passthrough``: the reason a
        passthrough goal is refused here); the caller clears ``gate.planning``."""
        gate, controller = self._gate, self._controller
        goal = await decode_sliced(TrajectoryGoalDecoder(body))
        owned.append(goal.points)  # decoded here: nobody else holds the list
        if goal.passthrough and no_passthrough is not None:
            raise GoalRejected(no_passthrough)
        names = self.joint_names(goal.joint_names)
        tolerances = self.tolerances(goal.tolerances, names)
        gate.check_still_wanted(generation)
        if goal.passthrough:
            self.passthrough.check_available()
        controller.check_can_start(self._backend.state, time.monotonic(), goal.preempt)
        gate.planning = f"trajectory of {len(goal.points)} points"
        planner = await check_sliced(controller.check_trajectory(names, goal.points, self._backend.state))
        owned.append(planner)  # the controller keeps the plan it finishes, never the planner
        await plan_tail(planner)
        frames = await self.passthrough.encode(planner) if goal.passthrough else None
        return PlannedGoal(goal.preempt, goal.passthrough, tolerances, planner, frames)

    def check_startable(self, planned: PlannedGoal, generation: int) -> None:
        """Refuse (``GoalRejected``) a planned goal that could not start now: shutting down, something
        ended motion since ``generation``, not ready, busy."""
        self._gate.check_still_wanted(generation)
        self._gate.check_not_planning_from_rest()  # a cell goal's part while a linear goal is planned
        if planned.passthrough:
            self.passthrough.check_available()
        self._controller.check_can_start(self._backend.state, time.monotonic(), planned.preempt)

    def start_planned(self, planned: PlannedGoal) -> tuple[str, float]:
        """Start a planned goal now (on the robot's next cycle); its id and planned duration."""
        goal_id, _ = self._new_goal()
        try:
            return goal_id, self._start_trajectory(
                goal_id, planned.preempt, planned.tolerances, planned.planner, planned.frames
            )
        except BaseException:
            self._keys_of.pop(goal_id, None)
            raise

    def result_key(self, goal_id: str) -> str | None:
        """The signing key of a running goal (None once its result is published)."""
        return self._keys_of.get(goal_id)

    def stop_goal(self, goal_id: str, reason: str) -> bool:
        """Stop the goal ``goal_id`` if it runs (it ends ``aborted`` with ``reason``); False if not."""
        if self._controller.active_goal_id != goal_id:
            return False
        self._controller.stop(reason, time.monotonic())
        self.publish_events()  # the robot stops a passthrough trajectory too (ended_here)
        self._status.publish()
        return True

    def cancel_goal(self, goal_id: str) -> bool:
        """Cancel the goal ``goal_id`` if it runs (it ends ``canceled``); False if not."""
        running = self._backend.passthrough_goal
        canceled = self._controller.cancel(goal_id)
        if canceled and running == goal_id:
            self._backend.cancel_passthrough()
        if canceled:
            self.publish_events()
            self._status.publish()
        return canceled

    def _start_trajectory(
        self,
        goal_id: str,
        preempt: bool,
        tolerances: Tolerances | None,
        planner: TrajectoryPlanner,
        frames: tuple[bytes, int] | None,
    ) -> float:
        if frames is not None:
            return self.passthrough.start(goal_id, planner, tolerances, frames, self._on_passthrough_result)
        return self._controller.accept_trajectory(
            goal_id,
            self._controller.joint_names,  # the planner's points are in the controller's joint order
            planner.points,
            self._backend.state,
            time.monotonic(),
            tolerances=tolerances,
            preempt=preempt,
            planner=planner,
        )

    def _on_passthrough_result(self, goal_id: str, code: int, why: str | None) -> None:
        if self.passthrough.finish(goal_id, code, why):
            self.publish_events()
            self._status.publish()

    # ---- move goals and cancel -------------------------------------------------------------------

    def on_move_goal(self, query: Any) -> None:
        """A point-to-point move goal to joint positions, decided at once; one to a TCP pose is
        handed to ``pose_goal`` (its IK is solved in slices, then ``start_move`` starts it)."""
        try:
            if self._gate.closing:
                raise GoalRejected(SHUTTING_DOWN)
            goal = move_goal.decode_move_goal(payload(query))
            self._gate.check_free_to_move()
            self._gate.check_not_planning_from_rest()
            if goal.pose is not None:
                if self.pose_goal is None:
                    raise GoalRejected(f"move goal.pose: robot {self._robot.name} has no arm kinematics")
                self.pose_goal(query, goal)
                return
            goal_id, duration = self.start_move(goal)
        except Exception as err:  # refused, or a bug: either way the client is answered, once
            self.refuse(query, "move", err)
            return
        self.accept(query, "move", goal_id, duration)

    def start_move(
        self, goal: MoveGoalMessage, positions: Sequence[float] | None = None
    ) -> tuple[str, float]:
        """Start a move goal now, to its ``positions`` (a pose goal's: the IK's ``positions``); its id
        and duration. Raises ``GoalRejected``."""
        if positions is not None:
            goal = dataclasses.replace(goal, positions=tuple(positions))
        names = self.joint_names(goal.joint_names)
        tolerances = self.tolerances(goal.tolerances, names)
        goal_id, _ = self._new_goal()
        return goal_id, self._accept_move(goal_id, goal, names, tolerances)

    def start_ready(self, plan: ReadyPlan, tolerances: Tolerances | None) -> tuple[str, float]:
        """Start a plan made for the pose the robot rests at (a linear goal's); its id and duration."""
        goal_id, _ = self._new_goal()
        try:
            state = self._backend.state
            return goal_id, self._controller.accept_planned(
                goal_id, plan, state, time.monotonic(), tolerances=tolerances
            )
        except BaseException:
            self._keys_of.pop(goal_id, None)  # never started: no result will use it
            raise

    def _accept_move(
        self, goal_id: str, goal: MoveGoalMessage, names: tuple[str, ...], tolerances: Tolerances | None
    ) -> float:
        try:
            return self._controller.accept_move(
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
            self._keys_of.pop(goal_id, None)  # never started: no result will use it
            raise

    def on_cancel(self, query: Any) -> None:
        """Cancel a goal (default: the active one, and a trajectory being planned)."""
        try:
            goal_id = goal_cancel.decode_cancel(payload(query))
        except MessageError as err:
            reply(query, {"canceled": False, "reason": str(err)})
            return
        controller = self._controller
        target = goal_id if goal_id is not None else controller.active_goal_id
        running = self._backend.passthrough_goal
        canceled = controller.cancel(goal_id)
        if canceled and running is not None and running == target:
            self._backend.cancel_passthrough()
        body: dict[str, Any] = {"canceled": canceled, "goal_id": target}
        # a goal being planned has no id yet: a cancel of no id, or of nothing active, cancels it
        planned = self._gate.interrupt_planning() if goal_id is None or not canceled else None
        if planned is not None:
            body["canceled"] = True
            body["planned"] = planned
        elif not canceled:
            body["reason"] = "no active goal" if target is None else f"goal {target} is not active"
        reply(query, body)
        self.publish_events()
