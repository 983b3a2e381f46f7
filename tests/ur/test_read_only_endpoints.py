"""A read-only robot, walked row by row through the endpoint table (publish/endpoints.py): every row
that would command it is refused before anything reads the message, even from the lease's holder;
every row it serves answers; its dashboard answers only the lines that ask (issue 31: a read-only
robot's dashboard service could pause a program). In-process daemon, a fake UR controller, a Zenoh
session on a loopback port the OS gave."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from tests.helpers import acquire_lease, fake_address, free_tcp_port, zenoh_ask
from tests.integration.conftest import running_daemon
from urdaemon.cell.robot_options import READ_ONLY_REASON
from urdaemon.fakeur.controller import FakeController
from urdaemon.publish import services
from urdaemon.publish.endpoints import ROBOT, ROBOT_ENDPOINTS, Kind, ReadOnly
from urdaemon.publish.envelope import encode

pytestmark = pytest.mark.timeout(120)

HOME = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
WAIT_S = 20.0
"""The longest any one answer may take (an upper bound on waiting, never a pause)."""


def _read_only_cell(address: str) -> str:
    ports = [free_tcp_port() for _ in range(4)]
    return f"""
cell: rocell
robots:
  - name: alice
    model: ur10e
    backend: ur
    address: {address}
    ports:
      {{reverse: {ports[0]}, script_sender: {ports[1]}, trajectory: {ports[2]}, script_command: {ports[3]}}}
    ur: {{read_only: true, startup: false, listen_address: 127.0.0.1}}
"""


async def _one(session: Any, key: str, body: Any = None, attachment: bytes | None = None) -> dict[str, Any]:
    replies = await zenoh_ask(session, key, body, attachment=attachment, timeout=WAIT_S)
    assert len(replies) == 1, (key, replies)
    return replies[0]


async def test_a_read_only_robot_refuses_every_commanding_row_and_serves_the_rest() -> None:
    fake = FakeController("ur10e", address=fake_address(), initial_positions=HOME, powered=True)
    await fake.start()
    try:
        async with running_daemon(_read_only_cell(fake.address)) as (_, client):
            alice = await client.robot("alice")
            keys, session = alice.keys, client.session
            grant = await acquire_lease(session, keys.cell, keys.robot)  # the lease is served
            token = grant.token
            events = client.subscribe(keys.events, 100)
            refused, served = [], []
            for row in ROBOT_ENDPOINTS:
                key = row.key(keys)
                if row.read_only is ReadOnly.REFUSED and row.kind is Kind.QUERYABLE:
                    # even the holder's token and no payload at all: refused before anything reads it
                    reply = await _one(session, key, attachment=token)
                    assert reply == {"v": 1, row.answer: False, "reason": READ_ONLY_REASON}, row.name
                    refused.append(row)
                elif row.read_only is ReadOnly.REFUSED and row.kind is Kind.SUBSCRIBER:
                    session.put(key, encode({"positions": HOME}), attachment=token)
                    event = await events.get_json(timeout=WAIT_S)
                    assert (event["kind"], event["key"], event["reason"]) == (
                        "command_rejected",
                        key,
                        READ_ONLY_REASON,
                    ), row.name
                    refused.append(row)
                elif row.read_only is ReadOnly.SERVED and row.service is not None:
                    reply = await _one(session, key, {}, attachment=token)
                    assert reply["ok"] is True, (row.name, reply)
                    served.append(row)
            assert {row.name for row in served} == {
                f"service/{spec.name}" for spec in (*services.SERVICES, services.STOP) if not spec.commanding
            }
            assert len(refused) == sum(row.read_only is ReadOnly.REFUSED for row in ROBOT_ENDPOINTS)
            assert (await _one(session, ROBOT.lease.key(keys), {"action": "show"}))["ok"] is True
            (unknown,) = await zenoh_ask(session, keys.goal_result("rocell-none"), timeout=WAIT_S)
            assert "'rocell-none': robot 'alice' has no such goal" in unknown["error"], unknown
            canceled = await _one(session, ROBOT.goal_cancel.key(keys), {})
            assert (canceled["canceled"], canceled["reason"]) == (False, "no active goal"), canceled
            for stream in (ROBOT.joint_states, ROBOT.tcp_pose, ROBOT.status, ROBOT.io):
                sub = client.subscribe(stream.key(keys), 10)
                assert await sub.get_json(timeout=WAIT_S), stream.name
                client.unsubscribe(sub)
            tokens = await asyncio.get_running_loop().run_in_executor(
                None, lambda: [str(r.ok.key_expr) for r in session.liveliness().get(keys.alive) if r.ok]
            )
            assert tokens == [keys.alive]
            assert fake.arm.q == pytest.approx(HOME, abs=1e-9)
    finally:
        await fake.close()


async def test_a_read_only_robots_dashboard_answers_only_the_lines_that_ask() -> None:
    """``pause`` (and every line that changes the robot) is refused naming the line; the server's
    queries are answered by the controller, however they are cased."""
    fake = FakeController("ur10e", address=fake_address(), initial_positions=HOME, powered=True)
    await fake.start()
    try:
        async with running_daemon(_read_only_cell(fake.address)) as (_, client):
            alice = await client.robot("alice")
            for line in ("pause", "play", "power off", "stop", "load /programs/x.urp", "quit", "nonsense"):
                reply = await alice.dashboard(line)
                assert reply["ok"] is False, line
                assert reply["reason"].startswith(
                    f"read-only robot (ur.read_only: true): dashboard line {line!r}"
                )
                assert "robotmode" in reply["reason"]
            for line in ("robotmode", "ROBOTMODE", "programState", "running", "get loaded program"):
                reply = await alice.dashboard(line)
                assert reply["ok"] is True, (line, reply)
                assert reply["reply"], line
    finally:
        await fake.close()
