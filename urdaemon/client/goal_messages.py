"""The messages of a robot's goals as a client follows them.

A goal's feedback and result are taken only when they carry the signature, under the key the
accepting reply gave (publish/signing.py), of the message and of the key it arrived on, and only when
they are messages of that goal: anything else on its keys is dropped and counted (``forged``).
``RobotGoals`` routes what arrives on a robot's goal keys to each goal's ``GoalInbox``, keeps what
comes before the accepting reply until the reply gives the goal's key, and fails every waiting goal
when the daemon stops serving the robot. The program reads an inbox through its ``GoalHandle``
(client/robot_client.py).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
from typing import Any

import zenoh

from urdaemon.client.session import ClientSession, Subscription
from urdaemon.errors import ConnectionLostError, UrDaemonError
from urdaemon.publish import signing
from urdaemon.publish.envelope import client_text
from urdaemon.publish.keys import CellKeys, RobotKeys

__all__ = [
    "LOST_GRACE_S",
    "MAX_QUEUED_FEEDBACK",
    "RESULT_POLL_S",
    "GoalInbox",
    "RobotGoals",
    "accepted_result_key",
]

RESULT_POLL_S = 0.5
"""While waiting for a result, ask the daemon for it this often (covers a missed publication)."""
LOST_GRACE_S = 1.0
"""When a robot's liveliness token disappears, how long a waiting goal still listens and asks for its
result before it fails (the token's deletion can overtake the result's publication)."""
MAX_QUEUED_FEEDBACK = 1000
"""Feedback kept for a reader that falls behind; older messages are dropped first."""
_EARLY_GOALS = 100
"""Goals, and messages of each, kept while their accepting reply has not come yet."""
_RESULT_KEY = re.compile(rf"[0-9a-f]{{{2 * signing.KEY_BYTES}}}")


def accepted_result_key(reply: dict[str, Any], robot: str, *, unsigned: bool) -> str | None:
    """The goal's key from its accepting reply: 64 hex characters; None only from a daemon older
    than leases (``unsigned``: it signs nothing). A daemon with leases always gives one: without, the
    goal's messages could not be told from forgeries, so that is an error naming ``result_key``."""
    key = reply.get("result_key")
    if isinstance(key, str) and _RESULT_KEY.fullmatch(key):
        return key
    if key is None and unsigned:
        return None
    raise UrDaemonError(
        f"robot {robot!r}: the daemon accepted goal {client_text(str(reply.get('goal_id')), 80)} "
        f"without a valid 'result_key' ({2 * signing.KEY_BYTES} hex characters): its result "
        "cannot be told from a forgery"
    )


class GoalInbox:
    """What arrived for one accepted goal, checked: its feedback and its one result."""

    def __init__(self, client: ClientSession, keys: RobotKeys, goal_id: str, result_key: str | None) -> None:
        self.client = client
        self.goal_id = goal_id
        self.result_key = result_key
        """The key the accepting reply gave: only messages signed with it are taken (None: a daemon
        that signs nothing, whose messages are taken as they come)."""
        self.result_query = keys.goal_result(goal_id)
        """Where the goal's result is published and can be asked for."""
        self.forged = 0
        """Messages on this goal's keys (or replies to its result query) that were not signed with
        its key for the key they came on, or are no message of this goal: ignored."""
        self.feedback: asyncio.Queue[dict[str, Any]] = asyncio.Queue(MAX_QUEUED_FEEDBACK)
        """Feedback not read yet (the newest ``MAX_QUEUED_FEEDBACK``)."""
        self.result: asyncio.Future[dict[str, Any]] = asyncio.get_running_loop().create_future()
        """The goal's result, or the error that says its end is unknown."""
        self._kinds = {keys.goal_feedback(goal_id): "feedback", self.result_query: "result"}

    def take(self, key: str, payload: bytes, attachment: bytes | None) -> str | None:
        """Take one message that arrived on ``key`` if that is this goal's feedback or result key,
        it is signed with the goal's key for that key, and it is one of this goal's messages (a
        result: with a ``status``); which it was (``"feedback"``, ``"result"``), None when not taken
        (counted in ``forged`` when it was on this goal's keys)."""
        kind = self._kinds.get(key)
        if kind is None:
            return None
        signed = self.result_key is None or signing.verify(self.result_key, key, payload, attachment)
        data = goal_message(payload, self.goal_id, result=kind == "result") if signed else None
        if data is None:
            self.forged += 1
            return None
        self._deliver(kind, data)
        return kind

    def _deliver(self, kind: str, data: dict[str, Any]) -> None:
        if kind == "result":
            if not self.result.done():
                self.result.set_result(data)
        else:
            if self.feedback.full():
                self.feedback.get_nowait()
            self.feedback.put_nowait(data)

    def fail(self, error: Exception) -> None:
        """The goal's end cannot be known: its result is ``error``, unless it came already."""
        if not self.result.done():
            self.result.set_exception(error)

    async def poll_result(self, timeout: float = 1.0) -> None:
        """Ask every queryable of the goal's result key (another session may answer it too: only a
        reply signed with the goal's key counts)."""
        try:
            replies = await self.client.query_replies(
                self.result_query, timeout=timeout, every_queryable=True
            )
        except UrDaemonError:
            return
        for reply in replies:  # a reply on another key than the result's is never the result
            if self.take(reply.key, reply.payload, reply.attachment) == "result":
                return


def goal_message(payload: bytes, goal_id: str, *, result: bool = False) -> dict[str, Any] | None:
    """``payload`` decoded if it is a message of goal ``goal_id`` (a ``result``: with a ``status``),
    else None (garbage is ignored)."""
    try:
        data = json.loads(payload)
    except ValueError:
        return None
    if not isinstance(data, dict) or data.get("goal_id") != goal_id:
        return None
    if result and not isinstance(data.get("status"), str):
        return None
    return data


class RobotGoals:
    """The goals one robot handle sent: the robot's goal messages routed to each goal's inbox until
    its result, and the robot's liveliness watched while any goal waits."""

    def __init__(self, client: ClientSession, keys: RobotKeys) -> None:
        self.client = client
        self.keys = keys
        self._goals: dict[str, GoalInbox] = {}
        self._early: dict[str, list[tuple[str, bytes, bytes | None]]] = {}
        self._sub: Subscription | None = None
        self._pump: asyncio.Task[None] | None = None
        self._alive_sub: Any = None
        self._lost: asyncio.Task[None] | None = None

    def follow(self) -> None:
        """Receive the robot's goal messages from now on (before a goal is sent: none is missed)."""
        if self._sub is None:
            self._sub = self.client.subscribe(self.keys.goal_messages, maxsize=10000)
            self._pump = self.client.spawn(self._pump_goals(self._sub))
            self._watch_liveliness()

    def add(self, goal_id: str, result_key: str | None) -> GoalInbox:
        """The inbox of a goal the daemon accepted, with what came for it before the reply."""
        inbox = GoalInbox(self.client, self.keys, goal_id, result_key)
        self._goals[goal_id] = inbox
        inbox.result.add_done_callback(lambda _: self._forget(goal_id))  # an asked-for result too
        for msg_key, payload, attachment in self._early.pop(goal_id, []):
            if inbox.take(msg_key, payload, attachment) == "result":
                self._forget(goal_id)
        return inbox

    def _forget(self, goal_id: str) -> None:
        self._goals.pop(goal_id, None)

    def _watch_liveliness(self) -> None:
        """Fail every waiting goal when the daemon stops serving this robot (its token disappears)."""
        loop = asyncio.get_running_loop()

        def on_token(sample: Any) -> None:
            if sample.kind == zenoh.SampleKind.DELETE:
                with contextlib.suppress(RuntimeError):
                    loop.call_soon_threadsafe(self._on_lost)

        self._alive_sub = self.client.session.liveliness().declare_subscriber(self.keys.alive, on_token)
        self.client.on_close(self._alive_sub.undeclare)

    def _on_lost(self) -> None:
        if self._goals and (self._lost is None or self._lost.done()):
            self._lost = self.client.spawn(self._settle_lost())

    async def _settle_lost(self) -> None:
        """The token is gone: a result published just before may still be on its way (or only be
        answerable), so take what was received, ask for each waiting goal's result, and fail only
        the goals whose result is still unknown after ``LOST_GRACE_S``."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + LOST_GRACE_S
        waiting = list(self._goals.values())
        await asyncio.gather(*(inbox.poll_result(timeout=LOST_GRACE_S) for inbox in waiting))
        pending = [inbox.result for inbox in waiting if not inbox.result.done()]
        if pending:
            await asyncio.wait(pending, timeout=max(0.0, deadline - loop.time()))
        error = ConnectionLostError(
            f"the daemon at {self.client.endpoint} stopped serving robot {self.keys.robot!r} "
            "before the goal ended"
        )
        for inbox in waiting:
            if not inbox.result.done():
                inbox.fail(error)
                self._forget(inbox.goal_id)

    async def _pump_goals(self, sub: Subscription) -> None:
        cell = CellKeys(self.keys.cell)
        async for key, payload, attachment in sub.samples():
            parsed = cell.parse(key)  # <cell>/<robot>/goal/<id>/<kind>, this robot's only
            mine = parsed is not None and parsed[0] == self.keys.robot
            message = CellKeys.goal_message(parsed[1]) if parsed is not None and mine else None
            if message is None:
                continue
            goal_id = message[0]
            inbox = self._goals.get(goal_id)
            if inbox is not None:
                # the inbox keeps its result; the robot need not track it further
                if inbox.take(key, payload, attachment) == "result":
                    self._forget(goal_id)
            elif goal_message(payload, goal_id) is not None:  # else someone else's garbage
                # before the accepting reply: checked once the reply gives the goal's key
                early = self._early.setdefault(goal_id, [])
                if len(early) < _EARLY_GOALS:
                    early.append((key, payload, attachment))
                if len(self._early) > _EARLY_GOALS:
                    self._early.pop(next(iter(self._early)))
