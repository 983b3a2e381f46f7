"""Cell goals from Python: trajectories that start together on several robots of a cell.

::

    goal = await send_cell_trajectory(client, "demo_cell", {"alice": points_a, "bob": points_b})
    result = await goal.result()  # {"status": "succeeded", "robots": {"alice": {...}, "bob": {...}}}

Each robot's command lease is taken first (as a robot's own goal takes it), and the tokens go with the
goal and with its cancel. The result is taken only when it carries the signature of the key the
accepting reply gave (publish/signing.py): anything else published on the result's key is ignored
and counted (``CellGoalHandle.ignored``).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import Mapping, Sequence
from typing import Any

from urdaemon.client.cell_connection import Client
from urdaemon.client.goal_messages import RESULT_POLL_S
from urdaemon.client.session import QUERY_TIMEOUT_S, Received, Subscription
from urdaemon.errors import GoalRejected, UrDaemonError, UrTimeoutError
from urdaemon.publish import signing
from urdaemon.publish.cell_goal import CellGoalRequest, cell_goal_body, lease_tokens_attachment
from urdaemon.publish.envelope import client_text
from urdaemon.publish.goal_cancel import cancel_body
from urdaemon.publish.keys import CellKeys
from urdaemon.publish.trajectory_goal import TrajectoryGoalRequest

__all__ = ["CellGoalHandle", "send_cell_trajectory"]


class CellGoalHandle:
    """A cell goal the daemon accepted: its id, each robot's part, and its one signed result."""

    def __init__(
        self, client: Client, keys: CellKeys, reply: dict[str, Any], tokens: bytes, sub: Subscription
    ) -> None:
        self.client = client
        self.keys = keys
        self.goal_id = str(reply["goal_id"])
        self.goals: dict[str, str] = dict(reply.get("goals") or {})
        """Each robot's part: its goal id (an ordinary goal of that robot)."""
        self.duration = float(reply.get("duration", 0.0))
        self.result_key: str = reply["result_key"]
        """The key the accepting reply gave (``signing.is_key``: checked by ``send_cell_trajectory``)."""
        self.ignored = 0
        """Messages on the result's key that did not carry its signature (not the daemon's)."""
        self._tokens = tokens
        self._sub = sub
        self._result: dict[str, Any] | None = None

    async def result(self, timeout: float | None = None) -> dict[str, Any]:
        """The cell goal's result (asking the daemon too, in case a publication was missed); raises
        ``UrTimeoutError`` after ``timeout`` seconds."""
        loop = asyncio.get_running_loop()
        deadline = None if timeout is None else loop.time() + timeout
        key = self.keys.goal_result(self.goal_id)
        while self._result is None:
            wait = RESULT_POLL_S if deadline is None else min(RESULT_POLL_S, deadline - loop.time())
            if wait <= 0:
                raise UrTimeoutError(f"cell goal {self.goal_id}: no result within {timeout} s")
            try:
                self._take(await self._sub.get_sample(wait), key)
            except UrTimeoutError:
                for received in await self.client.query_replies(key, timeout=1.0, every_queryable=True):
                    self._take(received, key)
        self.client.unsubscribe(self._sub)
        return self._result

    def _take(self, received: Received, key: str) -> None:
        if received.key != key or self._result is not None:
            return
        if not signing.verify(self.result_key, received.key, received.payload, received.attachment):
            self.ignored += 1
            return
        try:
            data = json.loads(received.payload)
        except (ValueError, RecursionError):
            data = None
        if isinstance(data, dict) and data.get("goal_id") == self.goal_id and "status" in data:
            self._result = data
        else:  # signed, yet no result of this goal: never taken as one
            self.ignored += 1

    async def cancel(self) -> dict[str, Any]:
        """Cancel every part (the reply says whether it was canceled, or why not)."""
        return await self.client.request(
            self.keys.goal_cancel, cancel_body(self.goal_id), attachment=self._tokens
        )


async def send_cell_trajectory(
    client: Client,
    cell: str,
    parts: Mapping[str, Sequence[dict[str, Any]] | Mapping[str, Any]],
    *,
    on_abort: str = "stop_all",
    timeout: float = QUERY_TIMEOUT_S,
) -> CellGoalHandle:
    """Send a cell goal: each robot's part is its points (or a whole trajectory goal body, with
    ``tolerances``, ``joint_names``, ``preempt``); all start together or none does. Raises
    ``GoalRejected`` with the daemon's reason (``"<robot>: <why>"``) or ``LeaseHeld`` when another
    client holds a robot's lease."""
    keys = CellKeys(cell)
    tokens: dict[str, str] = {}
    for name in parts:
        robot = await client.robot(name, cell=cell)
        await robot.lease.acquire()  # as a goal does: after a take-over it raises, never takes it back
        tokens[name] = robot.lease.token or ""
    robots: dict[str, TrajectoryGoalRequest | dict[str, Any]] = {
        name: dict(part) if isinstance(part, Mapping) else TrajectoryGoalRequest(tuple(part))
        for name, part in parts.items()
    }
    body = cell_goal_body(CellGoalRequest(robots, on_abort))
    attachment = lease_tokens_attachment(tokens)
    sub = client.subscribe(keys.goal_results)  # before the goal starts: its result cannot be missed
    try:
        reply = await client.request(keys.goal_trajectory, body, timeout=timeout, attachment=attachment)
    except BaseException:
        client.unsubscribe(sub)
        raise
    if not reply.get("accepted"):
        client.unsubscribe(sub)
        raise GoalRejected(str(reply.get("reason", "rejected without a reason")))
    if not signing.is_key(reply.get("result_key")):
        client.unsubscribe(sub)
        await _cancel_unfollowable(client, keys, reply, attachment)
        raise UrDaemonError(
            f"cell {cell!r}: the daemon accepted cell goal {client_text(str(reply.get('goal_id')), 80)} "
            f"without a valid 'result_key' ({2 * signing.KEY_BYTES} hex characters): its result cannot "
            "be told from a forgery, so it was canceled"
        )
    return CellGoalHandle(client, keys, reply, attachment, sub)


async def _cancel_unfollowable(client: Client, keys: CellKeys, reply: dict[str, Any], tokens: bytes) -> None:
    """Cancel an accepted cell goal whose result could not be trusted (best effort: the caller
    raises either way), so that no robot moves for a goal nobody can follow."""
    with contextlib.suppress(UrDaemonError):
        await client.request(keys.goal_cancel, cancel_body(str(reply.get("goal_id"))), attachment=tokens)
