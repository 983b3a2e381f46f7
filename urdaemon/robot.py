"""One robot served by the daemon: backend + motion controller + its Zenoh keys, supervised.

The backend clocks ``_on_cycle`` (the robot is the clock). That path only ticks the controller,
encodes the joint state and TCP pose and publishes them; everything else (goals, services,
status, IO) happens on requests or on slow timers.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import secrets
import time
import weakref
from collections import OrderedDict
from collections.abc import Awaitable, Callable, Coroutine, Sequence
from typing import Any

from urdaemon.backends.base import Backend
from urdaemon.cell.config import PublishOptions, Robot
from urdaemon.control import (
    GoalFeedback,
    GoalResult,
    GoalStatus,
    MotionController,
    Tolerances,
)
from urdaemon.control.trajectory import TrajectoryCheck, TrajectoryPlanner
from urdaemon.description.kinematics import DhKinematics
from urdaemon.errors import BackendError, GoalRejected, MessageError, UrDaemonError
from urdaemon.model import Lifecycle, RobotState
from urdaemon.publish import codec
from urdaemon.publish.codec import MAX_MESSAGE_BYTES, ToleranceMessage, TrajectoryGoalMessage
from urdaemon.publish.keys import RobotKeys
from urdaemon.publish.node import Matching, ZenohNode
from urdaemon.publish.trajectory_json import TrajectoryGoalDecoder

__all__ = ["RESTART_BACKOFF_S", "RobotRuntime"]

RESTART_BACKOFF_S = (0.1, 0.5, 1.0, 2.0, 5.0)
"""Delays before restarting a failed backend; the last one repeats."""
HEALTHY_CYCLES_S = 1.0
"""A backend that ran this many seconds' worth of cycles (at its rate) before failing restarts with
the first, shortest delay again: it was healthy, so this is a new fault, not the same one again."""
KEPT_RESULTS = 256
"""Finished goal results kept to answer late queries."""
PLANNING_SLICE_S = 0.00025
"""Longest stretch of trajectory decoding, checking, planning, encoding or freeing in one turn of the
event loop, for the whole process: every robot's sliced work shares one budget (``_sliced``), so N
robots receiving big goals at once still cost one slice per turn (a cycle is 2 ms; a young-generation
garbage collection inside a slice adds ~0.2 ms)."""
CHECK_STEPS = 4
"""Steps of a trajectory's check (a point each, a few µs) between two looks at the clock."""
RELEASE_ITEMS = 16
"""Objects freed between two looks at the clock when a goal's big objects are freed in slices."""
PAYLOADLESS_SERVICES = (
    "startup",
    "resend_program",
    "hand_back_control",
    "zero_ft_sensor",
    "end_force_mode",
    "start_tool_contact",
    "end_tool_contact",
)
"""Services without arguments: only nothing, an empty payload, ``{}`` or ``{"v": 1}`` is accepted."""
SHUTTING_DOWN = "daemon shutting down"
"""The reason every request gets once the daemon started to shut down."""
STOPPED_WHILE_PLANNING = "stopped while it was being planned (stop, cancel, hand_back_control or freedrive)"
"""The reason a trajectory goal is refused when something ended motion while it was being planned."""
TOOL_CONTACT_REASON = "tool contact: the tool touched something; the robot stopped and went back to it"
"""The reason a goal or stream ends when the robot reports a tool contact."""
TOOL_CONTACT_BUSY = "busy: tool contact: the robot rests where its tool touched; call end_tool_contact first"
"""The reason motion is refused between a tool contact and ``end_tool_contact``."""

Service = Callable[[bytes | None], Awaitable[dict[str, Any] | None]]
"""A service: the request's payload → what to add to its ``{"ok": true}`` reply (None: nothing)."""


class _RobotLog(logging.LoggerAdapter[logging.Logger]):
    def process(self, msg: Any, kwargs: Any) -> tuple[Any, Any]:
        return f"[{self.extra['robot'] if self.extra else '?'}] {msg}", kwargs


class RobotRuntime:
    """Serves one robot until cancelled; restarts its backend after failures without touching others."""

    def __init__(
        self,
        cell: str,
        robot: Robot,
        backend: Backend,
        controller: MotionController,
        node: ZenohNode,
        publish: PublishOptions,
        *,
        kinematics: DhKinematics | None = None,
    ) -> None:
        self.robot = robot
        self.backend = backend
        self.controller = controller
        self.node = node
        self.keys = RobotKeys(cell, robot.name)
        self.log = _RobotLog(logging.getLogger("urdaemon.robot"), {"robot": robot.name})
        self._kinematics = kinematics
        self._decimation = publish.joint_states_decimation
        self._status_period = 1.0 / publish.status_rate_hz
        self._io_period = 1.0 / publish.io_rate_hz
        self._encoder = codec.JointStateEncoder(robot.name, backend.state.joint_names)
        self._results: OrderedDict[str, bytes] = OrderedDict()
        self._goal_ids = itertools.count(1)
        self._goal_salt = secrets.token_hex(2)
        self._status_signature: tuple[Any, ...] = ()
        self._io_signature: tuple[Any, ...] = ()
        self._tasks: set[asyncio.Task[None]] = set()
        self._planning: str | None = None
        self._generation = 0
        """Counts what ends motion (stop, cancel, hand_back_control, freedrive on): a trajectory being
        planned is accepted only if it is still the same as when its planning began."""
        self._closing = False
        self._in_contact = False
        """The robot reported a tool contact and rests where it touched until ``end_tool_contact``."""
        """Set first when the runtime shuts down: every new request is answered ``SHUTTING_DOWN``."""
        self._running_services: set[str] = set()
        self.service_names: frozenset[str] = frozenset()
        """The services this robot answers (once declared)."""
        self._external_goal: str | None = None
        self._restarts = 0
        self._stream_rejections = 0
        self._frame = f"{robot.prefix}base"
        self._child = f"{robot.prefix}tool0"
        self._pub_joints: Any = None
        self._pub_pose: Any = None
        self._joints_wanted = Matching(False)
        self._pose_wanted = Matching(False)
        self._pub_status: Any = None
        self._pub_io: Any = None
        self._pub_events: Any = None

    # ---- lifecycle -----------------------------------------------------------------------------

    def declare(self) -> None:
        """Declare this robot's publishers, queryables, subscribers and liveliness token."""
        node, keys = self.node, self.keys
        self._pub_joints = node.publisher(keys.joint_states, realtime=True)
        self._joints_wanted = node.matching(self._pub_joints)
        self._pub_pose = node.publisher(keys.tcp_pose, realtime=True) if self._kinematics else None
        self._pose_wanted = node.matching(self._pub_pose) if self._pub_pose is not None else Matching(False)
        self._pub_status = node.publisher(keys.status)
        self._pub_io = node.publisher(keys.io)
        self._pub_events = node.publisher(keys.events)
        # every queryable and subscriber acts on its exact key only and refuses oversized messages
        # before reading them (publish/node.py)
        node.queryable(
            keys.goal_trajectory, self._on_trajectory_goal, max_bytes=MAX_MESSAGE_BYTES, answer="accepted"
        )
        node.queryable(keys.goal_move, self._on_move_goal, answer="accepted")
        node.queryable(keys.goal_cancel, self._on_cancel, answer="canceled")
        node.queryable(keys.goal_results, self._on_result_query, any_id=True)
        node.queryable(keys.service("stop"), self._on_stop, max_bytes=None)  # never refused for its payload
        services = self._services()
        for name, act in services.items():
            node.queryable(keys.service(name), self._on_service(name, act))
        self.service_names = frozenset({"stop", *services})
        self.backend.on_notice = self._publish_notice
        self.backend.on_change = self._publish_status
        for key, handler in (
            (keys.command_joint_position, self._on_stream_position),
            (keys.command_joint_velocity, self._on_stream_velocity),
            (f"{keys.base}/command/freedrive", self._on_freedrive),
        ):
            node.subscriber(key, handler, refused=self._on_refused_command)
        node.liveliness_token(keys.alive)

    def _services(self) -> dict[str, Service]:
        """Every service but ``stop`` (never refused) runs through ``_service`` (one reply, busy while
        it runs): name → what it does with the request's payload (an optional reply body to add)."""
        backend = self.backend
        services: dict[str, Service] = {
            "cycle_stats": self._cycle_stats,
            "dashboard": self._dashboard,
            "set_io": self._set_io,
            "set_payload": self._set_payload,
            "set_speed_slider": self._set_speed_slider,
            "set_tool_voltage": self._set_tool_voltage,
            "start_force_mode": self._start_force_mode,
        }
        actions: dict[str, Callable[[], Awaitable[None]]] = {
            "startup": lambda: backend.startup(),
            "resend_program": lambda: backend.resend_program(),
            "hand_back_control": self._hand_back_control,
            "zero_ft_sensor": lambda: backend.zero_ft_sensor(),
            "end_force_mode": lambda: backend.force_mode(None),
            "start_tool_contact": lambda: backend.tool_contact(True),
            "end_tool_contact": self._end_tool_contact,
        }
        for name in PAYLOADLESS_SERVICES:
            services[name] = _without_arguments(name, actions[name])
        return services

    async def run(self) -> None:
        """Run the backend, restarting it with backoff after any failure; also the status/IO timers."""
        try:
            async with asyncio.TaskGroup() as group:
                group.create_task(self._periodic_status())
                group.create_task(self._supervise())
        finally:
            # from now on every request answers "shutting down" (the daemon closes the backends after
            # this: nothing may be accepted that no cycle would end); requests in progress answer it too
            self._closing = True
            pending = list(self._tasks)
            for task in pending:
                task.cancel()
            if pending:
                await asyncio.gather(*pending, return_exceptions=True)

    async def _supervise(self) -> None:
        attempt = 0
        while True:
            cycles_before = self.backend.statistics().cycles
            try:
                await self.backend.run(self._on_cycle)
                reason = "backend stopped"
            except asyncio.CancelledError:
                self._closing = True  # before anything else: no request may start motion from now on
                self._end_motion(SHUTTING_DOWN)
                raise
            except Exception as err:  # any failure of one robot is contained here
                reason = f"backend failed: {type(err).__name__}: {err}"
                self.log.error("%s", reason, exc_info=not isinstance(err, UrDaemonError))
            self._restarts += 1
            self._end_motion(reason)
            state = self.backend.state
            state.lifecycle = Lifecycle.DISCONNECTED
            state.lifecycle_reason = reason
            self._publish_status()
            if self.backend.statistics().cycles - cycles_before >= HEALTHY_CYCLES_S * self.backend.rate_hz:
                attempt = 0  # a healthy run earns a fresh, short backoff: this is a new fault
            delay = RESTART_BACKOFF_S[min(attempt, len(RESTART_BACKOFF_S) - 1)]
            attempt += 1
            self.log.info("restarting backend in %.1f s", delay)
            await asyncio.sleep(delay)

    def _end_motion(self, reason: str) -> None:
        self._in_contact = False  # a restarted control script has no contact to rest in
        self.controller.abort(reason)
        state = self.backend.state
        state.program_running = False
        self._publish_events()
        self._publish_status()

    # ---- the cycle (hot path) --------------------------------------------------------------------

    def _on_cycle(self) -> None:
        backend = self.backend
        state = backend.state
        self.controller.tick(state, backend.command, state.monotonic_ns * 1e-9)
        if backend.catching_up:  # a newer package follows at once: it sends and publishes
            return
        backend.send_command()  # the robot's frame first, then everything users see
        if state.cycle % self._decimation == 0:
            # nothing is computed or encoded for a stream nobody subscribes to
            if self._joints_wanted.active:
                self._pub_joints.put(self._encoder.encode(state))
            if self._pose_wanted.active and self._kinematics is not None:
                pose = self._kinematics.tool_pose(state.positions)
                self._pub_pose.put(self._encoder.encode_pose(state, self._frame, self._child, pose))
        if self.controller.has_events:
            self._publish_events()
        if self._status_key() != self._status_signature:
            self._publish_status()

    def _publish_events(self) -> None:
        for event in self.controller.drain_events():
            if isinstance(event, GoalResult) and event.goal_id == self._external_goal:
                # the goal ended here (not ready, stopped, aborted), not by the robot's result: the
                # robot must stop its trajectory too, or it would carry on after play
                self._external_goal = None
                self.backend.cancel_passthrough()
            if isinstance(event, GoalFeedback):
                self.node.put(
                    self.keys.goal_feedback(event.goal_id), codec.encode_feedback(self.robot.name, event)
                )
            else:
                self._publish_result(event)

    def _publish_result(self, result: GoalResult) -> None:
        payload = codec.encode_result(self.robot.name, result)
        self._results[result.goal_id] = payload
        while len(self._results) > KEPT_RESULTS:
            self._results.popitem(last=False)
        self.node.put(self.keys.goal_result(result.goal_id), payload)
        log = self.log.info if result.status.value == "succeeded" else self.log.warning
        log(
            "goal %s %s%s", result.goal_id, result.status.value, f": {result.reason}" if result.reason else ""
        )

    # ---- status and IO ------------------------------------------------------------------------------

    def status_message(self) -> dict[str, Any]:
        """The status message body."""
        state = self.backend.state
        stats = self.backend.statistics()
        return {
            "robot": self.robot.name,
            "backend": self.backend.kind,
            "model": self.robot.model,
            "lifecycle": state.lifecycle.value,
            # never an empty reason while not ready, even before the backend worded its own
            "reason": state.lifecycle_reason or state.not_ready_reason(),
            "robot_mode": state.robot_mode.name,
            "safety_mode": state.safety_mode.name,
            "speed_slider": state.speed_slider,
            "speed_scaling": state.speed_scaling,
            "program_running": state.program_running,
            "ready": state.ready_for_motion,
            "active_goal": self.controller.active_goal_id,
            "rate_hz": self.backend.rate_hz,
            "cycles": stats.cycles,
            "missed_cycles": stats.missed_cycles,
            "late_cycles": stats.late_cycles,
            "restarts": self._restarts,
            "rejected_stream_commands": self._stream_rejections,
            # UR robots: does the robot's kinematics hash match the configured calibration (None: not checked)
            "calibration_ok": getattr(self.backend, "calibration_ok", None),
        }

    def io_message(self) -> dict[str, Any]:
        """The IO message body."""
        s = self.backend.state
        return {
            "robot": self.robot.name,
            "digital_out": list(s.digital_out),
            "configurable_out": list(s.configurable_out),
            "tool_out": list(s.tool_out),
            "analog_out": list(s.analog_out),
            "digital_in": list(s.digital_in),
            "configurable_in": list(s.configurable_in),
            "tool_in": list(s.tool_in),
            "analog_in": list(s.analog_in),
            "tool_voltage": s.tool_voltage,
            "payload": {"mass": s.payload_mass, "cog": list(s.payload_cog)},
        }

    def _status_key(self) -> tuple[Any, ...]:
        """What, when it changes, makes the status go out at once."""
        state = self.backend.state
        return (
            state.lifecycle,
            state.lifecycle_reason,
            state.robot_mode,
            state.safety_mode,
            # a real controller's scaling moves continuously: only a change of a percent is news
            round(state.speed_scaling, 2),
            state.program_running,
            self.controller.active_goal_id,
        )

    def _publish_status(self) -> None:
        self._status_signature = self._status_key()
        if self._pub_status is not None:
            self._pub_status.put(codec.encode(self.status_message()))

    def _publish_io(self) -> None:
        message = self.io_message()
        self._io_signature = tuple(str(v) for v in message.values())
        if self._pub_io is not None:
            self._pub_io.put(codec.encode(message))

    async def _periodic_status(self) -> None:
        last_status = last_io = 0.0
        while True:
            await asyncio.sleep(min(self._status_period, self._io_period))
            now = time.monotonic()
            try:
                if now - last_status >= self._status_period:
                    self._publish_status()
                    last_status = now
                io_signature = tuple(str(v) for v in self.io_message().values())
                if io_signature != self._io_signature or now - last_io >= 1.0:
                    self._publish_io()
                    last_io = now
            except Exception:  # a publishing error must not end this robot's (or the cell's) tasks
                self.log.exception("publishing status/IO failed")

    # ---- goals --------------------------------------------------------------------------------------

    def _new_goal_id(self) -> str:
        return f"{self.robot.name}-{self._goal_salt}-{next(self._goal_ids)}"

    def _joint_names(self, names: Sequence[str] | None) -> tuple[str, ...]:
        """Client joint names → controller names; names may leave out the robot prefix."""
        own = self.controller.joint_names
        if names is None:
            return own
        known = set(own)
        prefix = self.robot.prefix
        return tuple(n if n in known or f"{prefix}{n}" not in known else f"{prefix}{n}" for n in names)

    def _tolerances(self, message: ToleranceMessage, names: tuple[str, ...]) -> Tolerances | None:
        if message.path is None and message.goal is None and message.goal_time is None:
            return None
        own = self.controller.joint_names

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

    def _on_trajectory_goal(self, query: Any) -> None:
        if self._closing:
            self._reject_goal(query, "trajectory", GoalRejected(SHUTTING_DOWN))
            return
        if self._planning is not None:  # refused before reading a byte of it
            self._reject_goal(
                query, "trajectory", GoalRejected(f"busy: still planning trajectory {self._planning}")
            )
            return
        self._planning = "being decoded"
        # what ended motion before this query counts as before it: recorded now, not when it starts
        work = self._trajectory_goal(query, self._generation)
        self._spawn(work, query, {"accepted": False, "reason": SHUTTING_DOWN})

    async def _trajectory_goal(self, query: Any, generation: int) -> None:
        """Decode, check, plan (and for passthrough encode) a trajectory goal, all in slices between
        robot cycles, then start it; then free what it decoded and planned in slices too (a 5 000-point
        goal's points take ~1 ms to free at once)."""
        owned: list[object] = []
        await self._handle_trajectory_goal(query, generation, owned)
        with contextlib.suppress(asyncio.CancelledError):  # answered already: shutting down frees it
            await _release(owned)

    async def _handle_trajectory_goal(self, query: Any, generation: int, owned: list[object]) -> None:
        try:
            goal = await _decode_sliced(TrajectoryGoalDecoder(_payload(query)))
            owned.append(goal.points)  # decoded here: nobody else holds the list
            names = self._joint_names(goal.joint_names)
            tolerances = self._tolerances(goal.tolerances, names)
            self._check_still_wanted(generation)
            if goal.passthrough:
                problem = self.backend.passthrough_problem()
                if problem is not None:
                    raise GoalRejected(f"passthrough: {problem}")
            self.controller.check_can_start(self.backend.state, time.monotonic(), goal.preempt)
            self._planning = f"of {len(goal.points)} points"
            check = self.controller.check_trajectory(names, goal.points, self.backend.state)
            planner = await _check_sliced(check)
            owned.append(planner)  # the controller keeps the plan it finishes, never the planner
            await _plan_tail(planner)
            frames = await self._encode_passthrough(planner) if goal.passthrough else None
            self._check_still_wanted(generation)  # nothing ended motion while it was planned
            goal_id = self._new_goal_id()
            duration = self._start_trajectory(goal_id, goal.preempt, tolerances, planner, frames)
        except (MessageError, GoalRejected) as err:
            self._reject_goal(query, "trajectory", err)
            return
        except Exception as err:  # a bug must still answer the client, once
            self._fail_goal(query, "trajectory", err)
            return
        finally:  # cancelled (shutting down): the task's done-callback answers
            self._planning = None
        kind = "passthrough trajectory" if goal.passthrough else "trajectory"
        self._accept_goal(query, kind, goal_id, duration)

    def _check_still_wanted(self, generation: int) -> None:
        """Refuse a goal being planned if the daemon shuts down, or since ``generation`` something
        ended motion (stop, cancel, hand_back_control, freedrive), or freedrive is on."""
        if self._closing:
            raise GoalRejected(SHUTTING_DOWN)
        if generation != self._generation:
            raise GoalRejected(STOPPED_WHILE_PLANNING)
        self._check_free_to_move()

    def _interrupt_planning(self) -> str | None:
        """Make the trajectory goal being planned (if any) be refused; what it was, for the reply."""
        self._generation += 1
        if self._planning is None:
            return None
        return f"the trajectory goal being planned ({self._planning}) is refused"

    async def _encode_passthrough(self, planner: TrajectoryPlanner) -> tuple[bytes, int]:
        """Every point as the robot receives it, encoded in slices before the goal is accepted: a
        value the robot cannot carry (a segment over 2147 s) refuses the goal, nothing is in limbo."""
        points, velocities = planner.points, planner.velocities
        encode = self.backend.encode_passthrough_point
        frames: list[bytes] = []

        def step(deadline: float) -> bool:
            for i in range(len(frames), len(points)):
                point = points[i]
                segment = point.time_from_start - (points[i - 1].time_from_start if i else 0.0)
                try:
                    frames.append(encode(point.positions, velocities[i], point.accelerations, segment))
                except BackendError as err:
                    raise GoalRejected(f"passthrough: point {i}: {err}") from None
                if time.perf_counter() > deadline:
                    return i + 1 < len(points)
            return False

        await _sliced(step)
        return b"".join(frames), len(frames)

    def _start_trajectory(
        self,
        goal_id: str,
        preempt: bool,
        tolerances: Tolerances | None,
        planner: TrajectoryPlanner,
        frames: tuple[bytes, int] | None,
    ) -> float:
        if frames is not None:
            return self._start_passthrough(goal_id, planner, tolerances, frames)
        return self.controller.accept_trajectory(
            goal_id,
            self.controller.joint_names,  # the planner's points are in the controller's joint order
            planner.points,
            self.backend.state,
            time.monotonic(),
            tolerances=tolerances,
            preempt=preempt,
            planner=planner,
        )

    def _on_move_goal(self, query: Any) -> None:
        try:
            if self._closing:
                raise GoalRejected(SHUTTING_DOWN)
            goal = codec.decode_move_goal(_payload(query))
            self._check_free_to_move()
            names = self._joint_names(goal.joint_names)
            goal_id = self._new_goal_id()
            duration = self.controller.accept_move(
                goal_id,
                names,
                goal.positions,
                self.backend.state,
                time.monotonic(),
                duration=goal.duration,
                velocity_scale=goal.velocity_scale,
                acceleration_scale=goal.acceleration_scale,
                tolerances=self._tolerances(goal.tolerances, names),
                preempt=goal.preempt,
            )
        except (MessageError, GoalRejected) as err:
            self._reject_goal(query, "move", err)
            return
        except Exception as err:  # a bug must still answer the client, once
            self._fail_goal(query, "move", err)
            return
        self._accept_goal(query, "move", goal_id, duration)

    def _accept_goal(self, query: Any, kind: str, goal_id: str, duration: float) -> None:
        self.log.info("%s goal %s accepted (%.3f s)", kind, goal_id, duration)
        _reply(query, {"accepted": True, "goal_id": goal_id, "duration": duration})
        self._publish_events()  # a preempted goal's result goes out before the new goal's feedback
        self._publish_status()

    def _fail_goal(self, query: Any, kind: str, err: Exception) -> None:
        """Answer a goal that failed on a bug (call it from the except block: it logs the traceback)."""
        self.log.exception("%s goal failed", kind)
        _reply(query, {"accepted": False, "reason": _internal_error(err)})

    def _reject_goal(self, query: Any, kind: str, err: UrDaemonError) -> None:
        reason = err.reason if isinstance(err, GoalRejected) else str(err)
        self.log.warning("%s goal rejected: %s", kind, reason)
        _reply(query, {"accepted": False, "reason": reason})

    def _start_passthrough(
        self,
        goal_id: str,
        planner: TrajectoryPlanner,
        tolerances: Tolerances | None,
        frames: tuple[bytes, int],
    ) -> float:
        """Accept a goal the robot interpolates itself and send it its pre-encoded points (one write,
        no await in between). Everything that can refuse it ran before: accepting is the last step."""
        problem = self.backend.passthrough_problem()
        if problem is not None:
            raise GoalRejected(f"passthrough: {problem}")
        state = self.backend.state
        duration = self.controller.accept_external(
            goal_id, planner, state, time.monotonic(), tolerances=tolerances
        )
        try:
            self.backend.start_encoded_passthrough(goal_id, *frames, self._on_passthrough_result)
        except Exception as err:  # a bug: the goal was accepted, so it ends with its one result now
            self.log.exception("passthrough goal %s could not be sent", goal_id)
            self.controller.finish_external(goal_id, GoalStatus.ABORTED, _internal_error(err), state)
            return duration
        self._external_goal = goal_id
        return duration

    def _on_passthrough_result(self, goal_id: str, code: int) -> None:
        if self._external_goal == goal_id:
            self._external_goal = None
        status, reason = {
            0: (GoalStatus.SUCCEEDED, "the robot finished the trajectory"),
            1: (GoalStatus.CANCELED, "canceled on the robot"),
        }.get(code, (GoalStatus.ABORTED, "the robot reported that the trajectory failed"))
        if self.controller.finish_external(goal_id, status, reason, self.backend.state):
            self._publish_events()
            self._publish_status()

    def _on_cancel(self, query: Any) -> None:
        try:
            goal_id = codec.decode_cancel(_payload(query))
        except MessageError as err:
            _reply(query, {"canceled": False, "reason": str(err)})
            return
        target = goal_id if goal_id is not None else self.controller.active_goal_id
        external = self.controller.external_goal_id
        canceled = self.controller.cancel(goal_id)
        if canceled and external is not None and external == target:
            self.backend.cancel_passthrough()
        body: dict[str, Any] = {"canceled": canceled, "goal_id": target}
        # a goal being planned has no id yet: a cancel of no id, or of nothing active, cancels it
        planned = self._interrupt_planning() if goal_id is None or not canceled else None
        if planned is not None:
            body["canceled"] = True
            body["planned"] = planned
        elif not canceled:
            body["reason"] = "no active goal" if target is None else f"goal {target} is not active"
        _reply(query, body)
        self._publish_events()

    def _on_result_query(self, query: Any) -> None:
        key = str(query.key_expr)
        parts = key.split("/")
        goal_id = parts[-2] if len(parts) >= 2 else ""
        payload = self._results.get(goal_id)
        if payload is not None:
            query.reply(self.keys.goal_result(goal_id), payload)
        query.drop()

    # ---- streaming -------------------------------------------------------------------------------------

    def _on_stream_position(self, key: str, payload: bytes) -> None:
        state = self.backend.state
        try:
            message = codec.decode_stream_position(payload)
            self._check_accepting()
            assert message.positions is not None
            self.controller.stream_positions(
                self._joint_names(message.joint_names),
                message.positions,
                message.velocities,
                state,
                time.monotonic(),
            )
        except (MessageError, GoalRejected) as err:
            self._reject_stream(key, err)
        except Exception as err:  # a bug must not kill the subscriber; the client hears of it
            self.log.exception("streaming command failed")
            self._reject_stream(key, GoalRejected(_internal_error(err)))

    def _on_stream_velocity(self, key: str, payload: bytes) -> None:
        state = self.backend.state
        try:
            message = codec.decode_stream_velocity(payload)
            self._check_accepting()
            assert message.velocities is not None
            self.controller.stream_velocities(
                self._joint_names(message.joint_names), message.velocities, state, time.monotonic()
            )
        except (MessageError, GoalRejected) as err:
            self._reject_stream(key, err)
        except Exception as err:  # a bug must not kill the subscriber; the client hears of it
            self.log.exception("streaming command failed")
            self._reject_stream(key, GoalRejected(_internal_error(err)))

    def _on_refused_command(self, key: str, reason: str) -> None:
        """A command put on a wildcard key expression, or too large to read: it did nothing."""
        self._reject_stream(key, GoalRejected(reason))

    def _reject_stream(self, key: str, err: UrDaemonError) -> None:
        self._stream_rejections += 1
        reason = err.reason if isinstance(err, GoalRejected) else str(err)
        if self._stream_rejections <= 10 or self._stream_rejections % 100 == 0:
            self.log.warning(
                "streaming command on %s rejected (%d so far): %s", key, self._stream_rejections, reason
            )
        if self._pub_events is not None:
            self._pub_events.put(
                codec.encode(
                    {"robot": self.robot.name, "kind": "command_rejected", "key": key, "reason": reason}
                )
            )

    # ---- services ----------------------------------------------------------------------------------------

    def _on_stop(self, query: Any) -> None:
        planned = self._interrupt_planning()
        if self.controller.external_goal_id is not None:
            self.backend.cancel_passthrough()
        self.controller.stop("stop requested", time.monotonic())
        self._publish_events()
        _reply(query, {"ok": True} if planned is None else {"ok": True, "planned": planned})

    async def _cycle_stats(self, payload: bytes | None) -> dict[str, Any]:
        reset = codec.decode_cycle_stats(payload)
        backend = self.backend
        stats = backend.statistics()
        body = {
            "cycles": stats.cycles,
            "missed_cycles": stats.missed_cycles,
            "late_cycles": stats.late_cycles,
            "turnaround": backend.turnaround.summary(),
        }
        if reset:
            backend.turnaround.reset()
        return body

    def _check_accepting(self) -> None:
        """Refuse a streaming command while shutting down or in freedrive."""
        if self._closing:
            raise GoalRejected(SHUTTING_DOWN)
        self._check_free_to_move()

    def _check_free_to_move(self) -> None:
        """Refuse motion while freedrive is on or the robot rests where its tool touched something."""
        if self.backend.freedrive_active:
            raise GoalRejected(
                "busy: freedrive is on (stop sending freedrive commands, or send active: false)"
            )
        if self._in_contact:
            raise GoalRejected(TOOL_CONTACT_BUSY)

    def _on_freedrive(self, key: str, payload: bytes) -> None:
        try:
            active = codec.decode_freedrive(payload)
            if active:
                self._check_freedrive_can_start()
                self._generation += 1  # a trajectory planned from now on was planned before freedrive
            self.backend.freedrive(active, self.robot.motion.stream_timeout)
        except (MessageError, GoalRejected) as err:
            self._reject_stream(key, err)
        except BackendError as err:
            self._reject_stream(key, GoalRejected(str(err)))

    def _check_freedrive_can_start(self) -> None:
        if self._closing:
            raise GoalRejected(SHUTTING_DOWN)
        if self._in_contact:
            raise GoalRejected(TOOL_CONTACT_BUSY)
        self.controller.release_hold()
        if self.controller.mode != "idle":
            raise GoalRejected(
                f"busy: the robot is {self.controller.mode.replace('_', ' ')}; freedrive starts at rest"
            )
        if self._planning is not None:
            raise GoalRejected(
                f"busy: trajectory goal {self._planning} is being planned; freedrive starts at rest"
                " (cancel it first)"
            )

    async def _dashboard(self, payload: bytes | None) -> dict[str, Any]:
        line = codec.decode_dashboard(payload)
        ok, text = await self.backend.dashboard(line)
        return {"ok": ok, "reply": text}

    async def _end_tool_contact(self) -> None:
        await self.backend.tool_contact(False)
        if self._in_contact:
            # motion starts anew from where the robot rests, never from a setpoint of before the contact
            self._in_contact = False
            self.controller.abort(TOOL_CONTACT_REASON)

    async def _hand_back_control(self) -> None:
        self._interrupt_planning()  # the pendant program continues: nothing planned may start
        await self.backend.hand_back_control()

    def _publish_notice(self, kind: str, text: str) -> None:
        if kind == "tool_contact" and text == "contact":
            # the robot stopped on its own and goes back to where the tool touched: what we were sending
            # is over now, not when the goal's time runs out, and nothing moves it until end_tool_contact
            self._in_contact = True
            self._interrupt_planning()
            self.controller.abort(TOOL_CONTACT_REASON)
            self._publish_events()
            self._publish_status()
        if self._pub_events is not None:
            self._pub_events.put(codec.encode({"robot": self.robot.name, "kind": kind, "text": text}))

    async def _set_io(self, payload: bytes | None) -> dict[str, Any] | None:
        kind, pin, value = codec.decode_set_io(payload)
        await self.backend.set_io(kind, pin, value)
        self._publish_io()
        return None

    async def _set_payload(self, payload: bytes | None) -> dict[str, Any] | None:
        mass, cog = codec.decode_set_payload(payload)
        await self.backend.set_payload(mass, cog)
        self._publish_io()
        return None

    async def _set_speed_slider(self, payload: bytes | None) -> dict[str, Any] | None:
        fraction = codec.decode_speed_slider(payload)
        await self.backend.set_speed_slider(fraction)
        return None

    async def _set_tool_voltage(self, payload: bytes | None) -> dict[str, Any] | None:
        volts = codec.decode_tool_voltage(payload)
        await self.backend.set_tool_voltage(volts)
        return None

    async def _start_force_mode(self, payload: bytes | None) -> dict[str, Any] | None:
        from urdaemon.protocols.script_command import StartForceMode

        fields = codec.decode_force_mode(payload)
        await self.backend.force_mode(StartForceMode(**fields))
        return None

    def _on_service(self, name: str, act: Service) -> Callable[[Any], None]:
        def handle(query: Any) -> None:
            self._service(query, name, act)

        return handle

    def _service(self, query: Any, name: str, act: Service) -> None:
        """Run service ``name`` with the query's payload and answer once; a second call while it runs
        is refused, so a burst of requests never acts more than once at a time."""
        if self._closing:
            _reply(query, {"ok": False, "reason": SHUTTING_DOWN})
            return
        if name in self._running_services:
            _reply(
                query, {"ok": False, "reason": f"busy: {name} is still running; ask again once it answered"}
            )
            return
        self._running_services.add(name)
        payload = _payload(query)

        async def serve() -> None:
            try:
                extra = await act(payload)
            except (MessageError, BackendError) as err:
                self.log.warning("%s refused: %s", name, err)
                _reply(query, {"ok": False, "reason": str(err)})
            except Exception as err:  # a backend bug must still answer the client
                self.log.exception("%s failed", name)
                _reply(query, {"ok": False, "reason": _internal_error(err)})
            else:
                _reply(query, {"ok": True, **(extra or {})})

        task = self._spawn(serve(), query, {"ok": False, "reason": SHUTTING_DOWN})
        task.add_done_callback(lambda _: self._running_services.discard(name))

    def _spawn(
        self, work: Coroutine[Any, Any, None], query: Any, cancelled: dict[str, Any]
    ) -> asyncio.Task[None]:
        """Run ``work`` (which answers ``query`` once); cancelled (shutting down), even before its first
        step, the query is answered ``cancelled`` here instead, once."""
        task = asyncio.get_running_loop().create_task(work)
        self._tasks.add(task)

        def done(task: asyncio.Task[None]) -> None:
            self._tasks.discard(task)
            if task.cancelled():
                _reply(query, cancelled)

        task.add_done_callback(done)
        return task

    @property
    def state(self) -> RobotState:
        """The robot's latest state."""
        return self.backend.state


def _without_arguments(
    name: str, action: Callable[[], Awaitable[None]]
) -> Callable[[bytes | None], Awaitable[None]]:
    """A service that takes no arguments: its request is checked (garbage never acts), then it acts."""

    async def act(payload: bytes | None) -> None:
        codec.decode_empty(payload, name)
        await action()

    return act


_BATONS: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, asyncio.Lock] = weakref.WeakKeyDictionary()
"""One slicing baton per event loop, shared by every robot's sliced work."""


async def _sliced(step: Callable[[float], bool]) -> None:
    """Run ``step(deadline)`` until it returns False (done), one slice of PLANNING_SLICE_S per turn of
    the event loop for the whole process: each slice holds the loop's baton until the next turn, so
    however many robots slice at once, one turn runs one slice and every robot's cycle runs between."""
    loop = asyncio.get_running_loop()
    baton = _BATONS.get(loop)
    if baton is None:
        baton = _BATONS[loop] = asyncio.Lock()
    more = True
    while more:
        async with baton:
            more = step(time.perf_counter() + PLANNING_SLICE_S)
            await asyncio.sleep(0)  # the next slice, anyone's (the next stage's too), in a later turn


async def _release(owned: list[object]) -> None:
    """Free what the caller hands over in slices: it keeps no reference to the list's items, so a
    planner among them is ours to take apart attribute by attribute. What they reach is only dropped
    (a big list or tuple item by item, never changed): whoever else holds it keeps it intact."""
    dropped: list[object] = []

    def step(deadline: float) -> bool:
        for count in itertools.count(1):
            if owned:
                obj = owned.pop()
                if isinstance(obj, TrajectoryPlanner):
                    attributes = vars(obj)
                    dropped.extend(attributes.values())
                    attributes.clear()
                elif isinstance(obj, list | tuple):
                    dropped.extend(obj)
            elif dropped:
                obj = dropped.pop()
                if isinstance(obj, list | tuple) and len(obj) > RELEASE_ITEMS:
                    dropped.extend(obj)
            else:
                return False
            del obj
            if count % RELEASE_ITEMS == 0 and time.perf_counter() > deadline:
                return True
        return False  # unreachable: itertools.count never ends

    await _sliced(step)


async def _check_sliced(check: TrajectoryCheck) -> TrajectoryPlanner:
    """Check a trajectory's points in slices (``_sliced``), letting every robot's cycle run between."""
    try:
        await _sliced(_until_deadline(lambda: check.step(CHECK_STEPS)))
        return check.result()
    finally:
        check.close()


async def _decode_sliced(decoder: TrajectoryGoalDecoder) -> TrajectoryGoalMessage:
    """Decode a goal in slices (``_sliced``), letting every robot's cycle run between."""
    await _sliced(decoder.step)
    return decoder.result()


async def _plan_tail(planner: TrajectoryPlanner) -> None:
    """Plan a trajectory's tail in slices (``_sliced``), letting every robot's cycle run between."""
    await _sliced(_until_deadline(planner.plan_next))


def _until_deadline(advance: Callable[[], bool]) -> Callable[[float], bool]:
    """A ``_sliced`` step: call ``advance`` (True while there is more) until it is done or the slice's
    deadline passed; True while there is more."""

    def step(deadline: float) -> bool:
        while advance():
            if time.perf_counter() > deadline:
                return True
        return False

    return step


def _payload(query: Any) -> bytes | None:
    payload = query.payload
    return None if payload is None else bytes(payload.to_bytes())


def _reply(query: Any, body: dict[str, Any]) -> None:
    with contextlib.suppress(Exception):  # the querier may have timed out and gone
        query.reply(query.key_expr, codec.encode(body))
    with contextlib.suppress(Exception):
        query.drop()


def _internal_error(err: Exception) -> str:
    """The reason a client hears when a bug, not its request, made the command fail."""
    return f"internal error: {type(err).__name__}: {err}"
