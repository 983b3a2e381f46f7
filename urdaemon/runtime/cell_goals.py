"""The cell goal: trajectories that start together on several robots of the cell and end as one.

A cell goal (``<cell>/goal/trajectory``) gives each robot's part as the trajectory goal body its own
``<cell>/<robot>/goal/trajectory`` takes. Every part is decoded, checked and planned by its robot's
pipeline (runtime/goals.py), in slices between cycles; then, in one turn of the event loop, every
part is checked once more and all start, each on its robot's next cycle (so within one period of
each other), or none does and the reply names the robot that could not. Each part is an ordinary
goal of its robot: its own id, feedback, result and status (its key is not given out: the cell
goal's messages carry each robot's outcome).

The cell goal hears each part's result. With ``on_abort: stop_all`` (the default) the first part to
end other than succeeded stops the others (each ends ``aborted``, its reason naming the robot that
failed and why); with ``continue`` the others run on. It ends with exactly one result, once every
part has one, signed with its own key (over the key it goes out on), published on
``<cell>/goal/<G>/result`` and kept for late queries; ``<cell>/goal/cancel`` cancels every part.

A goal or cancel carries, as its attachment, a JSON object of each robot's command lease token;
each robot of the request must accept its token. The tokens are checked before the goal's body is
read or the planner marked busy (every robot they name must accept its own, and there must be some),
so a session without a lease cannot keep the planner busy; once the request is split, every robot
of it must have its token, and all are checked again just before the parts start.

Passthrough parts are refused: the robot starts a passthrough trajectory when its own program reads
it, which no daemon cycle can align with another robot's start.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import itertools
import json
import logging
import secrets
import time
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

from urdaemon.cell.robot_options import Robot
from urdaemon.control import GoalResult, GoalStatus
from urdaemon.errors import GoalRejected, MessageError, UrDaemonError
from urdaemon.publish import cell_goal, envelope, goal_cancel, signing
from urdaemon.publish.cell_goal import CellGoalDecoder, CellGoalMessage
from urdaemon.publish.endpoints import CELL, Endpoint
from urdaemon.publish.keys import CellKeys
from urdaemon.publish.node import ZenohNode
from urdaemon.runtime.goal_events import KEPT_RESULTS, put_signed
from urdaemon.runtime.goals import Goals, PlannedGoal
from urdaemon.runtime.lease_keeper import LeaseKeeper
from urdaemon.runtime.motion import RobotMotion, Ticket
from urdaemon.runtime.queries import SHUTTING_DOWN, Requests, internal_error, payload, reply
from urdaemon.runtime.slicing import release, sliced

__all__ = ["NO_TOKENS", "PASSTHROUGH_REFUSED", "CellGoals", "CellRobot", "lease_refusal"]

log = logging.getLogger(__name__)

PASSTHROUGH_REFUSED = (
    "passthrough is not supported in a cell goal: the robot starts a passthrough trajectory when its "
    "program reads it, which cannot be aligned with the other robots' starts; send this part without it"
)
"""Why a cell goal's passthrough part is refused."""
CANCELED = "canceled by request"
NO_TOKENS = (
    "lease: a cell goal needs each of its robots' command lease tokens as its attachment, a JSON "
    'object {"<robot>": "<token>", ...}; this one carries none'
)
"""Why a cell goal without lease tokens is refused (while the cell checks leases)."""


class CellRobot(Protocol):
    """What the cell goal uses of each of its robots: their parts of the runtime (robot.py's
    ``RobotRuntime`` is one; daemon.py hands over each of its own)."""

    @property
    def robot(self) -> Robot:
        """The robot's options: its name."""

    @property
    def goals(self) -> Goals:
        """Its goals: each part planned, checked, started, stopped, cancelled as its own goal."""

    @property
    def motion(self) -> RobotMotion:
        """Its motion: the generation a part is asked in, the gate claimed while the part plans."""

    @property
    def lease(self) -> LeaseKeeper:
        """Its command lease: whose token may command it."""


def lease_refusal(runtime: CellRobot, token: bytes | None) -> str | None:
    """Why ``token`` may not command ``runtime``'s robot (its command lease, as the robot's own goal
    queryables check it); None: it may."""
    return runtime.lease.book.refusal(token)


@dataclass(slots=True)
class _CellRun:
    """A cell goal that started: its parts, and what is known of how they ended."""

    goal_id: str
    key: str
    policy: str
    parts: dict[str, str]
    """Each robot's part: its goal id."""
    duration: float = 0.0
    """The longest part's planned duration."""
    results: dict[str, Any] = field(default_factory=dict)
    """Each ended part's result message, by robot."""
    failed: tuple[str, GoalStatus, str] | None = None
    """The first part to end other than succeeded: robot, status, reason."""
    canceled: bool = False
    done: bool = False


class CellGoals:
    """Owns the cell goal queryables, the cell goals that run, their results and the abort policy."""

    def __init__(self, node: ZenohNode, keys: CellKeys, runtimes: Sequence[CellRobot]) -> None:
        self._node = node
        self._keys = keys
        self._robots = {runtime.robot.name: runtime for runtime in runtimes}
        self._requests = Requests()
        self._closing = False
        self._planning = False
        self._running: dict[str, _CellRun] = {}
        self._results: OrderedDict[str, tuple[bytes, bytes]] = OrderedDict()
        self._ids = itertools.count(1)
        self._salt = secrets.token_hex(2)

    def endpoints(self) -> dict[Endpoint, Callable[[Any], None]]:
        """The rows of the endpoint table this part answers (the cell goal's), and their handlers
        (daemon.py declares them: publish/endpoints.py says each one's size limit and reply field)."""
        return {
            CELL.goal_trajectory: self.on_goal,
            CELL.goal_cancel: self.on_cancel,
            CELL.goal_results: self.on_result_query,
        }

    async def run(self) -> None:
        """Serve until cancelled; then every request in progress is answered ``SHUTTING_DOWN``."""
        try:
            await asyncio.Event().wait()
        finally:
            self._closing = True
            await self._requests.cancel_all()

    # ---- a cell goal arrives -----------------------------------------------------------------------

    def on_goal(self, query: Any) -> None:
        """A cell goal: refused at once while shutting down or while another is planned."""
        try:
            if self._closing:
                raise GoalRejected(SHUTTING_DOWN)
            tokens = cell_goal.decode_lease_tokens(_attachment(query))
            self._check_tokens(tokens)  # before it may keep the planner busy (review 16, M3)
            if self._planning:
                raise GoalRejected("busy: still planning another cell goal")
        except (MessageError, GoalRejected) as err:
            _refuse(query, err)
            return
        self._planning = True
        # what ended motion before this query counts as before it: recorded now, not when it starts
        generations = {name: runtime.motion.generation for name, runtime in self._robots.items()}
        work = self._goal(query, tokens, generations)
        self._requests.spawn(work, query, {"accepted": False, "reason": SHUTTING_DOWN})

    async def _goal(self, query: Any, tokens: dict[str, bytes], generations: dict[str, int]) -> None:
        owned: list[object] = []
        try:
            request = await _split(payload(query))
            parts = self._parts(request, tokens)
            with contextlib.ExitStack() as held:  # every ticket let go at the end, whatever happens
                tickets = {name: held.enter_context(self._claim(name, generations)) for name, _ in parts}
                planned = {name: await self._plan(name, request, tickets[name], owned) for name, _ in parts}
                run = self._start(request.on_abort, planned, tokens, generations)
        except (MessageError, GoalRejected) as err:
            _refuse(query, err)
        except Exception as err:  # a bug must still answer the client, once
            log.exception("cell goal failed")
            reply(query, {"accepted": False, "reason": internal_error(err)})
        else:
            body = {
                "goal_id": run.goal_id,
                "duration": run.duration,
                "goals": run.parts,
                "result_key": run.key,
            }
            reply(query, {"accepted": True, **body})
        finally:  # cancelled (shutting down): the task's done-callback answers
            self._planning = False
        with contextlib.suppress(asyncio.CancelledError):  # answered already: shutting down frees it
            await release(owned)

    def _check_tokens(self, tokens: dict[str, bytes]) -> None:
        """Refuse a cell goal whose lease tokens could never let it start, before its body is read:
        every robot they name must be served here and accept its token, and with the lease checked
        there must be at least one (every request names a robot, whose token it then lacks). So a
        session holding no lease cannot keep the planner busy with requests that are refused anyway."""
        if not tokens and any(lease_refusal(rt, None) is not None for rt in self._robots.values()):
            raise GoalRejected(NO_TOKENS)
        for name in tokens:
            self._runtime(name)
        self._check_leases(list(tokens), tokens)

    def _runtime(self, name: str) -> CellRobot:
        runtime = self._robots.get(name)
        if runtime is None:
            raise GoalRejected(
                f"{envelope.client_text(name)}: no robot {envelope.client_text(name)!r} in cell "
                f"{self._keys.cell!r}; its robots: {', '.join(sorted(self._robots))}"
            )
        return runtime

    def _parts(self, request: CellGoalMessage, tokens: dict[str, bytes]) -> list[tuple[str, CellRobot]]:
        """The robots of ``request``, each served here and commanded by its lease token, else refused."""
        parts = [(name, self._runtime(name)) for name in request.robots]
        self._check_leases([name for name, _ in parts], tokens)
        return parts

    def _check_leases(self, names: Sequence[str], tokens: dict[str, bytes]) -> None:
        for name in names:
            refusal = lease_refusal(self._robots[name], tokens.get(name))
            if refusal is not None:
                raise GoalRejected(f"{name}: {refusal}")

    def _claim(self, name: str, generations: dict[str, int]) -> Ticket:
        """Hold a robot's gate for its part (no robot goal is planned beside it), with the generation
        the cell goal was asked in; refused naming the robot."""
        try:
            return self._robots[name].motion.claim("a cell goal's part", generations[name])
        except GoalRejected as err:
            raise GoalRejected(f"{name}: {err.reason}") from None

    async def _plan(
        self, name: str, request: CellGoalMessage, ticket: Ticket, owned: list[object]
    ) -> PlannedGoal:
        """One robot's part planned by its robot's own pipeline; refused naming the robot."""
        goals = self._robots[name].goals
        try:
            return await goals.plan_trajectory(
                ticket, request.robots[name], owned, no_passthrough=PASSTHROUGH_REFUSED
            )
        except (MessageError, GoalRejected) as err:
            raise GoalRejected(f"{name}: {_reason(err)}") from None

    def _start(
        self,
        policy: str,
        planned: dict[str, PlannedGoal],
        tokens: dict[str, bytes],
        generations: dict[str, int],
    ) -> _CellRun:
        """Start every part in this turn of the loop, or none: everything that could refuse one is
        checked for all first."""
        if self._closing:
            raise GoalRejected(SHUTTING_DOWN)
        self._check_leases(list(planned), tokens)  # a lease may have changed hands meanwhile
        for name, goal in planned.items():
            try:
                self._robots[name].goals.check_startable(goal, generations[name])
            except GoalRejected as err:
                raise GoalRejected(f"{name}: {err.reason}") from None
        run = _CellRun(f"cell-{self._salt}-{next(self._ids)}", signing.new_key(), policy, {})
        durations: dict[str, float] = {}
        try:
            for name, goal in planned.items():
                run.parts[name], durations[name] = self._robots[name].goals.start_planned(goal)
        except Exception as err:  # checked above, so a bug: what started stops before its first cycle
            for name, goal_id in run.parts.items():
                self._robots[name].goals.stop_goal(goal_id, f"cell goal {run.goal_id} could not start: {err}")
            raise
        run.duration = max(durations.values())
        self._running[run.goal_id] = run
        for name, goal_id in run.parts.items():
            goals = self._robots[name].goals
            goals.events.result_listeners[goal_id] = functools.partial(self._part_ended, run, name)
        log.info(
            "cell goal %s accepted: %s", run.goal_id, ", ".join(f"{n} {g}" for n, g in run.parts.items())
        )
        for name, goal_id in run.parts.items():
            self._robots[name].goals.started(
                f"cell goal {run.goal_id}'s trajectory", goal_id, durations[name]
            )
        return run

    # ---- parts end, the cell goal ends -------------------------------------------------------------

    def _part_ended(self, run: _CellRun, robot: str, result: GoalResult, message: bytes) -> None:
        """A part's result was published: record it; stop the others if the policy says so; end the
        cell goal once every part ended (exactly once)."""
        run.results[robot] = json.loads(message)
        if result.status is not GoalStatus.SUCCEEDED and run.failed is None:
            run.failed = (robot, result.status, result.reason)
            if run.policy == "stop_all" and not run.canceled:
                why = f"cell goal {run.goal_id}: robot {robot!r} ended {result.status.value}: {result.reason}"
                for other, goal_id in run.parts.items():
                    if other not in run.results:
                        self._robots[other].goals.stop_goal(goal_id, why)
        if len(run.results) == len(run.parts) and not run.done:
            self._finish(run)

    def _finish(self, run: _CellRun) -> None:
        run.done = True
        self._running.pop(run.goal_id, None)
        if run.canceled:
            status, reason = "canceled", CANCELED
        elif run.failed is None:
            status, reason = "succeeded", ""
        else:
            robot, part_status, why = run.failed
            status = "canceled" if part_status is GoalStatus.CANCELED else "aborted"
            reason = f"robot {robot!r} ended {part_status.value}: {why}"
        # when the last part ended: now; no controller_time, the robots' clocks are their own results'
        body = {
            "host_time_ns": time.time_ns(),
            "goal_id": run.goal_id,
            "status": status,
            "robots": run.results,
            "reason": reason,
        }
        message = envelope.encode(body)
        on = self._keys.goal_result(run.goal_id)  # signed with the key it goes out on
        signature = signing.sign(run.key, on, message)
        self._results[run.goal_id] = (message, signature)
        while len(self._results) > KEPT_RESULTS:
            self._results.popitem(last=False)
        put_signed(self._node, on, message, signature)
        (log.info if status == "succeeded" else log.warning)(
            "cell goal %s %s%s", run.goal_id, status, f": {reason}" if reason else ""
        )

    def on_result_query(self, query: Any) -> None:
        """Answer a query for a finished cell goal's result, signed (nothing while it runs); for an id
        the cell does not know, an error reply naming it."""
        goal_id = self._keys.goal_of_result(str(query.key_expr))
        kept = self._results.get(goal_id) if goal_id is not None else None
        with contextlib.suppress(Exception):  # the querier may have timed out and gone
            if goal_id is not None and kept is not None:  # on the key its signature covers
                query.reply(self._keys.goal_result(goal_id), kept[0], attachment=kept[1])
            elif goal_id is not None and goal_id not in self._running:
                reason = f"cell goal {envelope.client_text(goal_id, 80)!r}: no such goal (never sent, or its "
                reason += f"result is no longer kept: the newest {KEPT_RESULTS} are)"
                query.reply_err(envelope.encode({"ok": False, "reason": reason}))
        with contextlib.suppress(Exception):
            query.drop()

    def on_cancel(self, query: Any) -> None:
        """Cancel a cell goal: every part still running ends ``canceled``. A cancel only stops the
        robots, so it needs no lease (publish/endpoints.py): anyone the access rules let in may."""
        try:
            goal_id = goal_cancel.decode_cell_cancel(payload(query))
            run = self._running.get(goal_id)
            if run is None:
                reply(
                    query,
                    {"canceled": False, "goal_id": goal_id, "reason": f"cell goal {goal_id} is not active"},
                )
                return
            running = [name for name in run.parts if name not in run.results]
        except MessageError as err:
            reply(query, {"canceled": False, "reason": _reason(err)})
            return
        run.canceled = True
        for name in running:
            self._robots[name].goals.cancel_goal(run.parts[name])
        reply(query, {"canceled": True, "goal_id": goal_id})


async def _split(body: bytes | None) -> CellGoalMessage:
    """A cell goal split into each robot's part, in slices (``sliced``)."""
    return await sliced(CellGoalDecoder(body).steps())


def _attachment(query: Any) -> bytes | None:
    attachment = query.attachment
    if attachment is None:
        return None
    limit = envelope.SMALL_MESSAGE_BYTES
    if len(attachment) > limit:  # refused by its size, never copied
        raise MessageError(f"lease tokens: attachment of {len(attachment)} bytes exceeds {limit} bytes")
    return bytes(attachment.to_bytes())


def _reason(err: UrDaemonError) -> str:
    return err.reason if isinstance(err, GoalRejected) else str(err)


def _refuse(query: Any, err: UrDaemonError) -> None:
    reason = _reason(err)
    log.warning("cell goal rejected: %s", reason)
    reply(query, {"accepted": False, "reason": reason})
