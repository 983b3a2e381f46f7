"""The client never hangs: a daemon that dies mid-goal ends the wait with an error, garbage is ignored."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
from typing import Any

import pytest
import zenoh

from tests.helpers import drain_in_background, free_tcp_port, wait_for_line
from tests.integration.conftest import ROOT, running_daemon
from urdaemon.client import Client
from urdaemon.errors import ConnectionLostError
from urdaemon.publish import signing
from urdaemon.publish.session_config import zenoh_config

pytestmark = pytest.mark.timeout(120)

HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]


async def test_a_daemon_killed_mid_goal_ends_result_and_feedback_with_connection_lost() -> None:
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "urdaemon",
            "serve",
            "--config",
            str(ROOT / "configs" / "dual_robot_mock.yaml"),
            "--listen",
            endpoint,
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    log: list[str] = []
    try:
        log += await wait_for_line(proc, "serving 2 robot(s)", timeout=60.0)
        drain_in_background(proc, log)
        async with await Client.connect(endpoint) as client:
            alice = await client.robot("alice")
            goal = await alice.move([0.8, *HOME[1:]], duration=20.0)
            feedback = goal.feedback()
            await feedback.__anext__()
            proc.send_signal(signal.SIGKILL)
            with pytest.raises(ConnectionLostError, match="alice"):
                await goal.result(timeout=15.0)
            with pytest.raises(ConnectionLostError):
                async for _ in feedback:
                    pass
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=10)


async def test_garbage_on_goal_keys_does_not_stop_the_client_from_tracking_goals() -> None:
    text = (ROOT / "configs" / "dual_robot_mock.yaml").read_text()
    async with running_daemon(text) as (daemon, client):
        alice = await client.robot("alice")
        first = await alice.move([0.1, *HOME[1:]], duration=0.5)
        assert (await first.result(timeout=10))["status"] == "succeeded"
        base = alice.keys.base
        for key, payload in (
            (f"{base}/goal/bogus/result", b"\\x80abc"),
            (f"{base}/goal/bogus/result", b"[]"),
            (f"{base}/goal/{first.goal_id}/result", b'{"goal_id": "someone-else", "status": "succeeded"}'),
            (f"{base}/goal/x/feedback", b"not json"),
        ):
            client.session.put(key, payload)
        goal = await alice.move(HOME, duration=0.5)
        received = [f async for f in goal.feedback()]
        assert all(f["goal_id"] == goal.goal_id for f in received)
        result = await goal.result(timeout=10)
        assert result["status"] == "succeeded"
        assert result["goal_id"] == goal.goal_id
        assert daemon.runtimes[0].status_message()["restarts"] == 0


async def test_messages_before_the_accepting_reply_are_checked_with_the_goals_key() -> None:
    """A stand-in daemon (no lease, so the client sends without one) publishes, before it answers the
    goal, a forged result and then the goal's signed one, then accepts with the goal's key. Before
    the signing the client took the first message it had buffered: the forgery."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    loop = asyncio.get_running_loop()
    server = await loop.run_in_executor(None, zenoh.open, zenoh_config("peer", [endpoint], []))
    key = signing.new_key()
    result_key = "earlycell/alice/goal/alice-1/result"
    forged = json.dumps({"goal_id": "alice-1", "status": "succeeded", "reason": "forged"}).encode()
    real = json.dumps({"goal_id": "alice-1", "status": "aborted", "reason": "the real one"}).encode()

    def on_move(query: Any) -> None:
        server.put(result_key, forged)
        server.put(result_key, real, attachment=signing.sign(key, result_key, real))
        reply = {"accepted": True, "goal_id": "alice-1", "duration": 1.0, "result_key": key}
        query.reply(str(query.key_expr), json.dumps(reply).encode())

    token = server.liveliness().declare_token("earlycell/alice/alive")
    queryable = server.declare_queryable("earlycell/alice/goal/move", on_move)
    try:
        async with await Client.connect(endpoint) as client:
            alice = await client.robot("alice", timeout=10.0)
            goal = await alice.move(HOME)
            result = await goal.result(timeout=10.0)
            assert result["reason"] == "the real one", result
            assert goal.forged == 1
            assert alice.lease.unchecked, "a daemon without leases: the client commands without one"
    finally:
        queryable.undeclare()  # type: ignore[no-untyped-call]
        token.undeclare()  # type: ignore[no-untyped-call]
        await loop.run_in_executor(None, server.close)
