"""One robot's goal messages: each goal's signing key, its feedback and result published signed, the
kept results answered to late queries, and who is told a result.

Every goal gets a key of its own (publish/signing.py) when it starts: the accepting reply gives it
to the client, and every feedback and result message of the goal (and every answer to a query for
its result) carries, as its Zenoh attachment, the signature of the message together with the key
it is published on (so a feedback cannot pass for a result). The signature is made when a message
is published, at the feedback rate (10 Hz by default) and once per result, never once per cycle; a
kept result keeps its signature, not the key.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import secrets
import time
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

import zenoh

from urdaemon.backends.base import Backend
from urdaemon.cell.robot_options import Robot
from urdaemon.control import GoalFeedback, GoalResult
from urdaemon.publish import envelope, signing
from urdaemon.publish.keys import RobotKeys
from urdaemon.publish.node import ZenohNode

__all__ = ["KEPT_RESULTS", "GoalEvents", "ResultListener", "put_signed", "unknown_goal"]

KEPT_RESULTS = 256
"""Finished goal results kept to answer late queries (each with its signature)."""

ResultListener = Callable[[GoalResult, bytes], None]
"""Told a goal's result (and its message as published) once it is published: a cell goal's part."""


def put_signed(node: ZenohNode, key: str, payload: bytes, attachment: bytes) -> None:
    """Publish once on ``key`` with ``attachment`` (a goal message's signature), dropped rather than
    blocking when congested (``ZenohNode.put``)."""
    with contextlib.suppress(zenoh.ZError):  # the session closed: nobody is left to hear it
        node.put(key, payload, attachment=attachment)


class GoalEvents:
    """Signs and publishes one robot's goal feedback and results; keeps the results for late queries."""

    def __init__(
        self,
        *,
        robot: Robot,
        backend: Backend,
        node: ZenohNode,
        keys: RobotKeys,
        log: logging.LoggerAdapter[logging.Logger],
    ) -> None:
        self._robot = robot
        self._backend = backend
        self._node = node
        self._keys = keys
        self._log = log
        self._results: OrderedDict[str, tuple[bytes, bytes]] = OrderedDict()
        """Finished goals' result messages and their signatures, oldest first."""
        self._keys_of: dict[str, str] = {}
        """Each running goal's signing key (until its result is published)."""
        self.result_listeners: dict[str, ResultListener] = {}
        """Who is told a goal's result when it is published, by goal id (told once, then forgotten)."""
        self._ids = itertools.count(1)
        self._salt = secrets.token_hex(2)

    def new_goal(self) -> str:
        """A new goal's id; its signing key is kept until its result is published (``forget``)."""
        goal_id = f"{self._robot.name}-{self._salt}-{next(self._ids)}"
        self._keys_of[goal_id] = signing.new_key()
        return goal_id

    def forget(self, goal_id: str) -> None:
        """A goal that never started: no result will use its key."""
        self._keys_of.pop(goal_id, None)

    def result_key(self, goal_id: str) -> str | None:
        """The signing key of a running goal (None once its result is published)."""
        return self._keys_of.get(goal_id)

    def _stamp(self) -> dict[str, Any]:
        """The time fields of a goal message: the newest state's (the cycle's, in a cycle)."""
        return envelope.state_time(self._backend.state, time.time_ns())

    def publish(self, event: GoalFeedback | GoalResult) -> None:
        """Publish a goal's feedback or result, signed with its goal's key."""
        if isinstance(event, GoalFeedback):
            key = self._keys_of.get(event.goal_id)
            if key is not None:  # at the feedback rate, never once per cycle
                message = envelope.encode_feedback(self._robot.name, event, self._stamp())
                on = self._keys.goal_feedback(event.goal_id)
                put_signed(self._node, on, message, signing.sign(key, on, message))
        else:
            self._publish_result(event)

    def _publish_result(self, result: GoalResult) -> None:
        message = envelope.encode_result(self._robot.name, result, self._stamp())
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

    def answer_result_query(self, query: Any) -> None:
        """Answer a query for a finished goal's result, signed; nothing while it runs (its result is
        published when it ends); for a goal id this robot does not know (never its goal, or its
        result no longer kept) an error reply naming the id, at once (``unknown_goal``)."""
        goal_id = self._keys.goal_of_result(str(query.key_expr))
        kept = self._results.get(goal_id) if goal_id is not None else None
        with contextlib.suppress(Exception):  # the querier may have timed out and gone
            if goal_id is not None and kept is not None:
                query.reply(self._keys.goal_result(goal_id), kept[0], attachment=kept[1])
            elif goal_id is not None and goal_id not in self._keys_of:
                query.reply_err(
                    envelope.encode({"ok": False, "reason": unknown_goal(self._robot.name, goal_id)})
                )
        with contextlib.suppress(Exception):
            query.drop()


def unknown_goal(robot: str, goal_id: str) -> str:
    """Why a result query for ``goal_id`` is answered with an error: no such goal (kept: the newest
    ``KEPT_RESULTS``)."""
    return (
        f"goal {envelope.client_text(goal_id, 80)!r}: robot {robot!r} has no such goal (never sent to "
        f"it, or its result is no longer kept: the newest {KEPT_RESULTS} are)"
    )
