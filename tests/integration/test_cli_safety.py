"""The CLI and the client API fail fast and say where and why (issue 13, finding 7; finding 6's
liveliness/result race). Commands run in-process (``run_cli_in_thread``) against a daemon in the
test's own loop.

Reproductions on the code before the fix: ``echo`` with no daemon hung forever; ``echo --count -5``
streamed forever; an unknown robot waited 5 s and listed nothing; an unknown service waited 60 s and
blamed the daemon; an invalid key printed Zenoh's Rust source path; there was no ``cancel``; the
``\\r`` progress went to stderr when it was a pipe or log and stopped short of 100 %; a client whose
robot's liveliness token vanished failed a goal whose result the daemon still held.
"""

from __future__ import annotations

import asyncio
import io
import json
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
import zenoh

from tests.helpers import free_tcp_port, run_cli_in_thread
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.client import Client, NoSuchRobot, NoSuchService, RobotClient
from urdaemon.daemon import Daemon
from urdaemon.publish.keys import RobotKeys
from urdaemon.publish.session_config import zenoh_config

pytestmark = pytest.mark.timeout(120)

HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
AWAY = [0.2, -1.4, 1.4, -1.5, -1.6, 0.1]
FAST_S = 30.0
"""Bound on a command that must fail fast (the old code waited forever, 60 s, or 5 s + nothing)."""


@pytest.fixture
async def served() -> AsyncIterator[tuple[Daemon, Client, str]]:
    async with running_daemon(TWO_MOCKS) as (daemon, client):
        yield daemon, client, daemon.listen_endpoints[0]


def _nobody() -> str:
    return f"tcp/127.0.0.1:{free_tcp_port()}"


async def test_echo_with_no_daemon_fails_naming_the_endpoint() -> None:
    endpoint = _nobody()
    run = await run_cli_in_thread(
        "echo", "testcell/alice/joint_states", "--connect", endpoint, timeout=FAST_S
    )
    assert run.code == 1, run
    assert endpoint in run.stderr
    assert "nothing answered" in run.stderr


@pytest.mark.parametrize(
    ("args", "problem"),
    [
        (("echo", "a/b", "--count", "-5"), "--count: must be a whole number >= 0, got -5"),
        (("echo", "a/b", "--timeout", "nan"), "--timeout: must be a finite number of seconds"),
        (("service", "alice", "stop", "--timeout", "-1"), "--timeout: must be a finite number"),
        (("move", "alice", "--joints", "0,0,0,0,0,0", "--duration", "0"), "--duration: must be"),
        (("calibration", "--address", "127.0.0.1", "--output", "x", "--port", "0"), "--port"),
    ],
)
async def test_numeric_arguments_are_validated(args: tuple[str, ...], problem: str) -> None:
    run = await run_cli_in_thread(*args, "--connect", _nobody(), timeout=FAST_S)
    assert run.code == 2, run
    assert problem in run.stderr


async def test_an_invalid_key_names_no_rust_source_path() -> None:
    run = await run_cli_in_thread("echo", "a//b", "--connect", _nobody(), timeout=FAST_S)
    assert run.code == 2, run
    assert "not a valid key expression" in run.stderr
    assert ".rs:" not in run.stderr, run.stderr
    assert "/.cargo/" not in run.stderr, run.stderr


async def test_an_unknown_robot_fails_fast_and_lists_the_robots(
    served: tuple[Daemon, Client, str],
) -> None:
    _, client, endpoint = served
    run = await run_cli_in_thread(
        "move", "carol", "--joints", "0,0,0,0,0,0", "--connect", endpoint, timeout=FAST_S
    )
    assert run.code == 1, run
    assert endpoint in run.stderr
    assert "testcell/alice" in run.stderr, run.stderr
    assert "testcell/bob" in run.stderr, run.stderr
    with pytest.raises(NoSuchRobot) as caught:
        await client.robot("carol")
    assert caught.value.robots == [("testcell", "alice"), ("testcell", "bob")]


async def test_an_unknown_service_fails_fast_and_lists_the_services(
    served: tuple[Daemon, Client, str],
) -> None:
    _, client, endpoint = served
    run = await run_cli_in_thread("service", "alice", "bogus", "--connect", endpoint, timeout=FAST_S)
    assert run.code == 1, run
    said = run.stdout + run.stderr  # the daemon's refusal (stdout), or the client's own (stderr)
    assert "no service 'bogus'" in said, said
    assert all(name in said for name in ("set_io", "stop", "resend_program")), said
    keys = RobotKeys("nocell", "alice")  # nothing serves its keys at all
    nowhere = RobotClient(client, keys, client.lease(keys))
    with pytest.raises(NoSuchService) as caught:
        await nowhere.call("stop", timeout=60.0)
    assert endpoint in str(caught.value)
    assert "nocell/alice/service/stop" in str(caught.value)


NO_LEASE = TWO_MOCKS.replace("cell: testcell", "cell: testcell\ncommand_lease: false")
"""The test cell without command leases: any client may cancel any goal, as before leases."""


async def test_cancel_command_cancels_the_active_goal() -> None:
    """About ``cancel``'s own replies and exit codes, so in a cell without leases (it says so):
    with leases on, another process's cancel is refused naming the holder
    (test_client_lease.py::test_cancel_from_another_process_is_refused_naming_the_holder)."""
    async with running_daemon(NO_LEASE) as (daemon, client):
        await _cancel_from_the_cli(client, daemon.listen_endpoints[0])


async def _cancel_from_the_cli(client: Client, endpoint: str) -> None:
    alice = await client.robot("alice")
    goal = await alice.move(AWAY, duration=30.0)
    run = await run_cli_in_thread("cancel", "alice", "--connect", endpoint, timeout=FAST_S)
    assert run.code == 0, run
    assert json.loads(run.stdout)["canceled"] is True
    result = await goal.result(timeout=10.0)
    assert result["status"] == "canceled", result
    again = await run_cli_in_thread(
        "cancel", "alice", "--goal", goal.goal_id, "--connect", endpoint, timeout=FAST_S
    )
    assert again.code == 1, again  # nothing to cancel any more: said, not hidden
    assert json.loads(again.stdout)["canceled"] is False


async def test_move_writes_no_carriage_returns_when_stderr_is_not_a_terminal(
    served: tuple[Daemon, Client, str],
) -> None:
    _, _, endpoint = served
    joints = ",".join(repr(v) for v in AWAY)
    run = await run_cli_in_thread(
        "move", "bob", "--joints", joints, "--duration", "2", "--connect", endpoint, timeout=FAST_S
    )
    assert run.code == 0, run
    assert "\r" not in run.stderr, run.stderr
    assert "%" not in run.stderr, run.stderr
    assert json.loads(run.stdout)["status"] == "succeeded"


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


class _FakeGoal:
    """A goal whose feedback stops short of the end (feedback is sent at 10 Hz), then succeeds."""

    goal_id = "g-1"

    async def feedback(self) -> AsyncIterator[dict[str, Any]]:
        for progress in (0.2, 0.6, 0.97):
            yield {"progress": progress}

    async def result(self, timeout: float | None = None) -> dict[str, Any]:
        return {"status": "succeeded", "goal_id": self.goal_id}


async def test_move_progress_on_a_terminal_ends_at_100_percent(capsys: pytest.CaptureFixture[str]) -> None:
    from urdaemon.cli import move_command

    tty = _Tty()
    assert await move_command._follow(_FakeGoal(), move_command._ProgressBar(tty)) == 0
    shown = tty.getvalue()
    assert shown.endswith("\r  100.0 %\n"), repr(shown)
    assert json.loads(capsys.readouterr().out)["status"] == "succeeded"


async def test_a_vanished_token_still_asks_for_the_result_before_failing_the_goal() -> None:
    """A stand-in daemon accepts a goal, holds its result (answerable, never published: the
    publication raced the token's deletion), and drops the robot's liveliness token."""
    endpoint = _nobody()
    loop = asyncio.get_running_loop()
    conf = zenoh_config("peer", [endpoint], [])
    server = await loop.run_in_executor(None, zenoh.open, conf)
    result = {"v": 1, "robot": "alice", "goal_id": "alice-1", "status": "succeeded"}

    def on_move(query: Any) -> None:
        query.reply(str(query.key_expr), json.dumps({"accepted": True, "goal_id": "alice-1"}).encode())

    def on_result(query: Any) -> None:
        query.reply("racecell/alice/goal/alice-1/result", json.dumps(result).encode())

    token = server.liveliness().declare_token("racecell/alice/alive")
    queryables = [
        server.declare_queryable("racecell/alice/goal/move", on_move),
        server.declare_queryable("racecell/alice/goal/*/result", on_result),
    ]
    try:
        async with await Client.connect(endpoint) as client:
            alice = await client.robot("alice", timeout=10.0)
            goal = await alice.move(HOME)
            lost = asyncio.Event()
            watch = client.session.liveliness().declare_subscriber(
                "racecell/alice/alive",
                lambda sample: loop.call_soon_threadsafe(lost.set),
            )
            token.undeclare()  # type: ignore[no-untyped-call]
            await asyncio.wait_for(lost.wait(), 10.0)
            assert await goal.result(timeout=10.0) == result
            watch.undeclare()
    finally:
        for queryable in queryables:
            queryable.undeclare()  # type: ignore[no-untyped-call]
        await loop.run_in_executor(None, server.close)


async def test_zenoh_config_is_the_base_and_connect_still_names_the_endpoint(
    served: tuple[Daemon, Client, str], tmp_path: Path
) -> None:
    """A JSON5 config file (as the TLS helper writes one) is the session's base; the file's own
    endpoint is overridden by --connect, so a stale file cannot send a command elsewhere."""
    _, _, endpoint = served
    config = tmp_path / "client.json5"
    config.write_text(
        '{\n  // a stale endpoint: --connect wins\n  connect: { endpoints: ["' + _nobody() + '"] },\n}\n',
        encoding="utf-8",
    )
    joints = ",".join(repr(v) for v in AWAY)
    move = await run_cli_in_thread(
        "move", "bob", "--joints", joints, "--duration", "1", "--connect", endpoint,
        "--zenoh-config", str(config), timeout=FAST_S,
    )  # fmt: skip
    assert move.code == 0, move
    assert json.loads(move.stdout)["status"] == "succeeded"
    async with await Client.connect(endpoint, config_file=str(config)) as client:
        assert [r for c, r in await client.robots()] == ["alice", "bob"]


async def test_a_zenoh_config_that_cannot_be_used_is_named(tmp_path: Path) -> None:
    missing = tmp_path / "missing.json5"
    run = await run_cli_in_thread(
        "lease", "alice", "--zenoh-config", str(missing), "--connect", _nobody(), timeout=FAST_S
    )
    assert run.code == 2, run
    assert f"--zenoh-config {str(missing)!r} is not a file" in run.stderr
    broken = tmp_path / "broken.json5"
    broken.write_text("{ mode: ", encoding="utf-8")
    run = await run_cli_in_thread(
        "echo", "a/b", "--zenoh-config", str(broken), "--connect", _nobody(), timeout=FAST_S
    )
    assert run.code == 1, run
    assert f"cannot read the Zenoh config {broken}" in run.stderr, run.stderr
