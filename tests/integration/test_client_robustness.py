"""The client never hangs: a daemon that dies mid-goal ends the wait with an error, garbage is ignored."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

from tests.helpers import drain_in_background, free_tcp_port, wait_for_line
from tests.integration.conftest import ROOT, running_daemon
from urdaemon.client import Client
from urdaemon.errors import ConnectionLostError

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
