"""Review of issue 13: Ctrl-C on ``urdaemon move`` while it still waits for the goal's accept reply.

In-process: the daemon and ``move`` share this test's loop. Ctrl-C is what ``asyncio.run`` does
with it, a cancel of the command's task, delivered at the moment the move request is on its way.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from typing import Any

import pytest

from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.cli import move_command
from urdaemon.cli.exit_codes import EXIT_INTERRUPTED
from urdaemon.cli.parser import build_parser
from urdaemon.client import Client

pytestmark = pytest.mark.timeout(120)

AWAY = [0.2, -1.4, 1.4, -1.5, -1.6, 0.1]


async def test_ctrl_c_while_waiting_for_the_accept_reply_cancels_the_goal(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Reproduction: ``move alice --duration 30``, Ctrl-C while the move request is on its way.
    Before the fix the command exited at once, the reply was lost, and the daemon accepted the goal
    a moment later with nobody following it: alice moved for 30 s. Now the command waits for the
    reply and cancels the goal it names: a `canceled` result comes, and the exit code is 130."""
    async with running_daemon(TWO_MOCKS) as (daemon, client):
        results = client.subscribe("testcell/alice/goal/*/result")
        real_request = Client.request
        interrupted: list[asyncio.Task[Any]] = []

        async def request(self: Client, key: str, body: Any = None, **kw: Any) -> dict[str, Any]:
            sent = asyncio.ensure_future(real_request(self, key, body, **kw))
            if key.endswith("/alice/goal/move") and not interrupted:
                interrupted.append(command)
                command.cancel()  # Ctrl-C, with the request on its way
            return await sent

        monkeypatch.setattr(Client, "request", request)
        endpoint = daemon.listen_endpoints[0]
        args = build_parser().parse_args(
            [
                "move",
                "alice",
                f"--joints={','.join(repr(v) for v in AWAY)}",
                "--duration",
                "30",
                "--connect",
                endpoint,
            ]
        )
        command = asyncio.ensure_future(move_command.move(args))
        code: int | None = None
        with contextlib.suppress(asyncio.CancelledError):  # how the command ended before the fix
            code = await asyncio.wait_for(asyncio.shield(command), 60.0)
        assert interrupted, "the move request was never sent"
        monkeypatch.undo()
        # the goal the daemon accepted ends, canceled, well before its 30 s
        _key, payload = await results.get(timeout=10.0)
        result = json.loads(payload)
        assert result["status"] == "canceled", result
        assert daemon.runtimes[0].controller.active_goal_id is None
        assert code == EXIT_INTERRUPTED
        err = capsys.readouterr().err
        assert f"goal {result['goal_id']} canceled" in err, err
