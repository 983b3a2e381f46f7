"""A goal's result and feedback are taken only from the daemon (issue 16, contract section 2).

Another Zenoh session can publish on a goal's keys and answer queries on them; only the daemon knows
the goal's key (given in the accepting reply) and signs with it. Reproduction on the code before the
signing: a raw session published ``{"goal_id": <id>, "status": "succeeded"}`` on
``<cell>/alice/goal/<id>/result`` while the goal ran, and the client's ``result()`` returned it at once,
seconds before alice got there; a forged answer to the client's result query did the same.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import pytest
import zenoh

from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.client import Client, GoalHandle, Received, RobotClient
from urdaemon.daemon import Daemon
from urdaemon.errors import UrTimeoutError
from urdaemon.publish.session_config import zenoh_config

pytestmark = pytest.mark.timeout(120)

AWAY = [0.2, -1.4, 1.4, -1.5, -1.6, 0.1]
DURATION_S = 60.0
"""The real goal's length: far longer than any test. The forgeries go out while it runs, then the
test cancels it, so the daemon's own result says ``canceled`` where every forgery says
``succeeded``."""
WAIT_S = 20.0
"""Bound of every wait for a message (a busy machine is slow, never this slow)."""
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


async def _publish_until_received(
    client: Client, forger: Any, key: str, payload: bytes, attachment: bytes | None = None
) -> None:
    """Publish ``payload`` (with ``attachment``) on ``key`` from ``forger`` until ``client``'s session
    receives it: then the client's goal subscription (same session, declared before) has received it
    too."""
    watch = client.subscribe(key, 1000)
    try:
        for _ in range(ROUTED_TRIES):
            forger.put(key, payload, attachment=attachment)
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


def _the_daemons_cancel(daemon: Daemon, result: dict[str, Any]) -> None:
    """``result`` is the daemon's own result of the goal canceled mid-move (every forgery says
    ``succeeded``), and alice was stopped short of the goal."""
    assert "forged" not in result, result
    assert result["status"] == "canceled", f"not the daemon's result of the cancel: {result}"
    assert not _at_target(daemon), "alice got there: the goal was not canceled mid-move"


async def _canceled_after(
    alice: RobotClient, goal: GoalHandle, asked: asyncio.Event | None = None
) -> dict[str, Any]:
    """The goal's result, cancelled once the forgery was weighed: at once, or (``asked``) once the
    forger has answered a result query of ``result()`` (that query's replies are weighed before
    ``result()`` returns)."""
    waiting = asyncio.ensure_future(goal.result(timeout=WAIT_S))
    try:
        if asked is not None:
            async with asyncio.timeout(WAIT_S):
                await asked.wait()
        assert not waiting.done(), f"result() returned while alice still moved: {waiting.result()}"
        assert (await alice.cancel(goal.goal_id))["canceled"] is True
        return await waiting
    finally:
        waiting.cancel()


async def _started(client: Client) -> tuple[RobotClient, GoalHandle]:
    alice = await client.robot("alice")
    return alice, await alice.move(AWAY, duration=DURATION_S)


async def _started_with_signed_feedback(
    client: Client, forger: Any
) -> tuple[RobotClient, GoalHandle, Received]:
    """Start the goal with ``forger`` listening to alice's goal feedback (its route checked first,
    so the first feedback reaches it); the goal and the first feedback as the daemon signed it."""
    loop = asyncio.get_running_loop()
    alice = await client.robot("alice")
    heard: asyncio.Queue[Received] = asyncio.Queue()

    def on_sample(sample: Any) -> None:
        attachment = None if sample.attachment is None else sample.attachment.to_bytes()
        item = Received(str(sample.key_expr), sample.payload.to_bytes(), attachment)
        loop.call_soon_threadsafe(heard.put_nowait, item)

    listening = forger.declare_subscriber(alice.keys.goal_feedback("*"), on_sample)
    try:
        probe = alice.keys.goal_feedback("probe")
        for _ in range(ROUTED_TRIES):  # the client's probe reaches the forger: so will the daemon's
            client.session.put(probe, b"{}")
            with contextlib.suppress(TimeoutError):
                if (await asyncio.wait_for(heard.get(), 0.1)).key == probe:
                    break
        else:
            raise AssertionError("the forger's subscription was never routed")
        goal = await alice.move(AWAY, duration=DURATION_S)
        async with asyncio.timeout(WAIT_S):
            while (feedback := await heard.get()).key != alice.keys.goal_feedback(goal.goal_id):
                pass
        return alice, goal, feedback
    finally:
        listening.undeclare()


async def test_a_result_and_feedback_published_by_another_session_are_ignored_and_counted() -> None:
    async with daemon_and_forger() as (daemon, client, forger):
        alice, goal = await _started(client)
        forged_feedback = _forged(goal, progress=1.0, time_from_start=DURATION_S)
        await _publish_until_received(client, forger, alice.keys.goal_feedback(goal.goal_id), forged_feedback)
        forged_result = _forged(goal, status="succeeded", reason="")
        await _publish_until_received(client, forger, alice.keys.goal_result(goal.goal_id), forged_result)
        stream = goal.feedback()
        async with asyncio.timeout(WAIT_S):  # the daemon's own feedback still comes
            feedback = [await anext(stream)]
        result = await _canceled_after(alice, goal)
        _the_daemons_cancel(daemon, result)
        feedback += [f async for f in stream]
        assert not [f for f in feedback if "forged" in f], "forged feedback was delivered"
        assert goal.forged >= 2, goal.forged


async def test_a_forged_answer_to_the_result_query_is_ignored_and_counted() -> None:
    async with daemon_and_forger() as (daemon, client, forger):
        alice, goal = await _started(client)
        await _forger_answers_the_result_query(
            daemon, forger, alice, goal, _forged(goal, status="succeeded", reason="")
        )


async def test_the_daemons_signed_feedback_republished_as_the_result_is_ignored() -> None:
    """H3 (contract 16b, decision 6): a signature covers the key the message is published on, and a
    result must have this goal's id and a status. Reproduction on 94dec3a: a raw session took the
    daemon's first signed feedback message of the goal and re-published it, with its attachment, on
    ``<cell>/alice/goal/<id>/result``; the client's ``result()`` returned that feedback (no
    ``status``) at once, while alice still moved."""
    async with daemon_and_forger() as (daemon, client, forger):
        alice, goal, feedback = await _started_with_signed_feedback(client, forger)
        key = alice.keys.goal_result(goal.goal_id)
        await _publish_until_received(client, forger, key, feedback.payload, feedback.attachment)
        result = await _canceled_after(alice, goal)
        _the_daemons_cancel(daemon, result)
        assert goal.forged >= 1, goal.forged


async def test_the_daemons_signed_feedback_given_as_the_answer_to_the_result_query_is_ignored() -> None:
    """H3, asked: a raw session answers the client's query for the result with the daemon's signed
    feedback (payload and attachment). Reproduction on 94dec3a: ``result()`` returned the feedback."""
    async with daemon_and_forger() as (daemon, client, forger):
        alice, goal, feedback = await _started_with_signed_feedback(client, forger)
        await _forger_answers_the_result_query(
            daemon, forger, alice, goal, feedback.payload, feedback.attachment
        )


async def _forger_answers_the_result_query(
    daemon: Any, forger: Any, alice: Any, goal: Any, payload: bytes, attachment: bytes | None = None
) -> None:
    """The forger answers every query for the goal's result with ``payload`` (and ``attachment``);
    once it has answered one, the goal is canceled: the client must return the daemon's cancel, and
    count the forgery."""
    key = alice.keys.goal_result(goal.goal_id)
    answered = asyncio.Event()
    loop = asyncio.get_running_loop()

    def answer(query: Any) -> None:
        query.reply(key, payload, attachment=attachment)
        loop.call_soon_threadsafe(answered.set)

    queryable = forger.declare_queryable(key, answer)
    try:
        result = await _canceled_after(alice, goal, answered)  # asks every 0.5 s meanwhile
        _the_daemons_cancel(daemon, result)
        assert goal.forged >= 1, goal.forged
    finally:
        queryable.undeclare()
