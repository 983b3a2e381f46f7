"""A goal's result and feedback are taken only from the daemon (issue 16, contract section 2).

Another Zenoh session can publish on a goal's keys and answer queries on them; only the daemon knows
the goal's key (given in the accepting reply) and signs with it. Reproduction on the code before the
signing: a raw session published ``{"goal_id": <id>, "status": "succeeded"}`` on
``<cell>/alice/goal/<id>/result`` while the goal ran, and the client's ``result()`` returned it at once,
seconds before alice got there; a forged answer to the client's result query did the same.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import pytest
import zenoh

from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.client import Client, GoalHandle, RobotClient
from urdaemon.daemon import Daemon
from urdaemon.errors import UrTimeoutError
from urdaemon.publish.node import zenoh_config

pytestmark = pytest.mark.timeout(120)

AWAY = [0.2, -1.4, 1.4, -1.5, -1.6, 0.1]
DURATION_S = 3.0
"""The real goal's length: the forgeries go out at its start."""
ROUTED_TRIES = 100
"""Publications of a forgery until the client's session is seen to receive it (routes are set up
asynchronously); each waits at most 0.1 s for it."""


@asynccontextmanager
async def daemon_and_forger() -> AsyncIterator[tuple[Daemon, Client, Any]]:
    """The two-mock cell, a client of it, and a forger: a bare Zenoh session with no urdaemon code,
    connected to the daemon's endpoint in Zenoh's client mode (the daemon forwards what it publishes
    to the other sessions connected to it, as in the issue's probe)."""
    loop = asyncio.get_running_loop()
    async with running_daemon(TWO_MOCKS) as (daemon, client):
        conf = zenoh_config("client", [], [daemon.listen_endpoints[0]])
        forger = await loop.run_in_executor(None, zenoh.open, conf)
        try:
            yield daemon, client, forger
        finally:
            await loop.run_in_executor(None, forger.close)


def _forged(goal: GoalHandle, **fields: Any) -> bytes:
    message = {"v": 1, "robot": "alice", "goal_id": goal.goal_id, "forged": True, **fields}
    return json.dumps(message).encode()


async def _publish_until_received(client: Client, forger: Any, key: str, payload: bytes) -> None:
    """Publish ``payload`` on ``key`` from ``forger`` until ``client``'s session receives it: then the
    client's goal subscription (same session, declared before) has received it too."""
    watch = client.subscribe(key, 1000)
    try:
        for _ in range(ROUTED_TRIES):
            forger.put(key, payload)
            try:
                while (await watch.get(timeout=0.1))[1] != payload:
                    pass
                return
            except UrTimeoutError:
                continue
        raise AssertionError(f"the forgery on {key} never reached the client")
    finally:
        client.unsubscribe(watch)


def _at_target(daemon: Daemon) -> bool:
    positions = daemon.runtimes[0].backend.state.positions
    return all(abs(a - b) <= 0.01 for a, b in zip(positions, AWAY, strict=True))


async def _started(client: Client) -> tuple[RobotClient, GoalHandle]:
    alice = await client.robot("alice")
    return alice, await alice.move(AWAY, duration=DURATION_S)


async def test_a_result_and_feedback_published_by_another_session_are_ignored_and_counted() -> None:
    async with daemon_and_forger() as (daemon, client, forger):
        alice, goal = await _started(client)
        forged_feedback = _forged(goal, progress=1.0, time_from_start=DURATION_S)
        await _publish_until_received(client, forger, alice.keys.goal_feedback(goal.goal_id), forged_feedback)
        forged_result = _forged(goal, status="succeeded", reason="")
        await _publish_until_received(client, forger, alice.keys.goal_result(goal.goal_id), forged_result)
        result = await goal.result(timeout=30.0)
        assert _at_target(daemon), "result() returned before alice got there: the forged result"
        assert "forged" not in result, result
        assert result["status"] == "succeeded", result
        feedback = [f async for f in goal.feedback()]
        assert feedback, "the daemon's own feedback was dropped too"
        assert not [f for f in feedback if "forged" in f], "forged feedback was delivered"
        assert goal.forged >= 2, goal.forged


async def test_a_forged_answer_to_the_result_query_is_ignored_and_counted() -> None:
    async with daemon_and_forger() as (daemon, client, forger):
        alice, goal = await _started(client)
        key = alice.keys.goal_result(goal.goal_id)
        forged = _forged(goal, status="succeeded", reason="")
        answered = asyncio.Event()
        loop = asyncio.get_running_loop()

        def answer(query: Any) -> None:
            query.reply(key, forged)
            loop.call_soon_threadsafe(answered.set)

        queryable = forger.declare_queryable(key, answer)
        try:
            result = await goal.result(timeout=30.0)  # asks for the result every 0.5 s meanwhile
            assert answered.is_set(), "the client never asked: the forgery was not put to the test"
            assert _at_target(daemon), "result() returned before alice got there: the forged answer"
            assert "forged" not in result, result
            assert result["status"] == "succeeded", result
            assert goal.forged >= 1, goal.forged
        finally:
            queryable.undeclare()
