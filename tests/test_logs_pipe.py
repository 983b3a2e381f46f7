"""A daemon whose stderr nobody reads for 10 s keeps both robots moving (issue 13, finding 3).

Reproduction: ``urdaemon serve`` runs as a subprocess with stderr on a pipe this test does not read
for 10 s, two ``ur`` robots against in-process fake controllers; while both move, a client sends a
flood of goals with an unknown (long) field name, each of which the daemon logs as a rejection. Before
the fix every log call wrote straight to stderr: once the 64 KiB pipe was full the event loop blocked
in ``write`` for the rest of the pause, both control programs timed out on their reverse read and
halted, and the goals running then were aborted.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
import subprocess
import sys
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import drain_in_background, fake_address, free_tcp_port
from urdaemon.client import Client, RobotClient
from urdaemon.errors import UrDaemonError
from urdaemon.fakeur.controller import FakeController

pytestmark = pytest.mark.timeout(180)

ROOT = Path(__file__).resolve().parents[1]
HOME = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
AWAY = [0.3, -1.4, 1.4, -1.5, -1.6, 0.2]
PAUSE_S = 10.0
"""How long nobody reads the daemon's stderr (the issue's scenario)."""
MAX_GOALS = 12
"""Goals per robot during the pause (each ~1 s): a bound, the pause normally ends first."""
FLOOD_FIELD = "unknown_field_" + "x" * 400


def _cell(alice: str, bob: str, listen: str) -> str:
    def ports() -> str:
        p = [free_tcp_port() for _ in range(4)]
        return f"{{reverse: {p[0]}, script_sender: {p[1]}, trajectory: {p[2]}, script_command: {p[3]}}}"

    robots = ""
    for name, model, address in (("alice", "ur10e", alice), ("bob", "ur3e", bob)):
        robots += f"""
  - name: {name}
    model: {model}
    backend: ur
    address: {address}
    ports: {ports()}
    ur: {{startup: true, listen_address: 127.0.0.1}}
"""
    return f"cell: pipecell\nzenoh: {{listen: [{listen}]}}\nrobots:{robots}"


class _ProgramEnds(logging.Handler):
    """Counts the fakes' 'program ... ended' records: a control program that halted."""

    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.ended: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        message = record.getMessage()
        if " program " in message and " ended" in message:
            self.ended.append(message)


@pytest.fixture
def program_ends() -> Iterator[_ProgramEnds]:
    handler = _ProgramEnds()
    logger = logging.getLogger("urdaemon.fakeur")
    old_level = logger.level
    logger.setLevel(logging.INFO)
    logger.addHandler(handler)
    try:
        yield handler
    finally:
        logger.removeHandler(handler)
        logger.setLevel(old_level)


async def _ready(client: Client, robot: RobotClient) -> None:
    sub = client.subscribe(robot.keys.status, 100)
    try:
        for _ in range(2000):
            status = await sub.get_json(timeout=20.0)
            if status.get("ready"):
                return
        raise AssertionError(f"{robot.name} never became ready")
    finally:
        client.unsubscribe(sub)


async def _move_back_and_forth(robot: RobotClient, paused: asyncio.Event, outcomes: list[str]) -> None:
    """Goals one after the other until the pause is over; each outcome ('succeeded', ...) noted."""
    for i in range(MAX_GOALS):
        if paused.is_set():
            return
        try:
            goal = await robot.move(AWAY if i % 2 == 0 else HOME, duration=1.0)
            result = await goal.result(timeout=30.0)
        except UrDaemonError as err:
            outcomes.append(f"{robot.name}: {type(err).__name__}: {err}")
            continue
        outcomes.append(str(result.get("status")) if result.get("status") == "succeeded" else str(result))


async def _flood(client: Client, robot: RobotClient, fake: FakeController, paused: asyncio.Event) -> int:
    """Goals the daemon rejects and logs (an unknown field name echoed), until the pause is over."""
    sent = 0
    body: dict[str, Any] = {"positions": HOME, FLOOD_FIELD: 1}
    token = (await robot.ensure_lease()).encode()  # the robot's holder floods: each goal is decoded
    while not paused.is_set() and sent < 5_000:
        with contextlib.suppress(UrDaemonError):
            await client.query(robot.keys.goal_move, body, timeout=1.0, attachment=token)
        sent += 1
        # one per 3 of the robot's cycles (at most ~170 a second): each logged 450 bytes, the 64 KiB
        # pipe fills in under a second, and the flood tests the log, not how many queries a busy
        # machine's daemon can decode
        await fake.cycles_pass(3)
    return sent


async def test_unread_stderr_for_10_s_halts_no_program_and_loses_no_goal(
    tmp_path: Path, program_ends: _ProgramEnds
) -> None:
    listen = f"tcp/127.0.0.1:{free_tcp_port()}"
    fake_alice = FakeController("ur10e", address=fake_address(), initial_positions=HOME)
    fake_bob = FakeController("ur3e", address=fake_address(), initial_positions=HOME)
    config = tmp_path / "cell.yaml"
    config.write_text(_cell(fake_alice.address, fake_bob.address, listen), encoding="utf-8")
    async with fake_alice, fake_bob:
        daemon = subprocess.Popen(
            [sys.executable, "-m", "urdaemon", "serve", "--config", str(config)],
            cwd=ROOT,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,  # read by nobody until the pause is over
            text=True,
        )
        stderr: list[str] = []
        try:
            client = await Client.connect(listen, timeout=30.0)
            async with client:
                alice = await client.robot("alice", timeout=30.0)
                bob = await client.robot("bob", timeout=30.0)
                await asyncio.gather(_ready(client, alice), _ready(client, bob))
                results = client.subscribe("pipecell/*/goal/*/result", 10_000)
                paused = asyncio.Event()
                outcomes: list[str] = []
                movers = [
                    asyncio.create_task(_move_back_and_forth(robot, paused, outcomes))
                    for robot in (alice, bob)
                ]
                flood = asyncio.create_task(_flood(client, alice, fake_alice, paused))
                await asyncio.sleep(PAUSE_S)  # the pause itself is the scenario
                paused.set()
                drain_in_background(daemon, stderr)  # the reader comes back
                sent = await flood
                await asyncio.wait_for(asyncio.gather(*movers), 60.0)
                published: Counter[str] = Counter()
                while True:
                    try:
                        key, _ = await results.get(timeout=2.0)
                    except UrDaemonError:
                        break
                    published[key] += 1
                halted = list(program_ends.ended)  # before the daemon stops (which ends them)
        finally:
            if daemon.poll() is None:
                daemon.send_signal(signal.SIGTERM)
            code = await asyncio.get_running_loop().run_in_executor(None, daemon.wait, 60)
            if not stderr:  # never drained (the test failed early): read what is there
                stderr.append(daemon.stderr.read() if daemon.stderr else "")
    log = "".join(stderr)
    assert sent > 100, f"the flood sent only {sent} goals"
    assert outcomes, "no goal ran during the pause"
    assert all(o == "succeeded" for o in outcomes), f"{outcomes}\n{log[-3000:]}"
    assert len(published) == len(outcomes), published
    assert set(published.values()) == {1}, published  # exactly one result per goal
    assert halted == [], halted
    assert code == 0, log[-3000:]
    assert "suppressed" in log, log[-3000:]  # the flood was rate limited, and said so
    assert FLOOD_FIELD not in log or log.count(FLOOD_FIELD) <= 40


async def test_a_client_field_name_cannot_forge_a_daemon_log_line(tmp_path: Path) -> None:
    """Reproduction: a goal whose unknown field name holds ``\\n`` and a fake log line; the daemon's
    rejection warning echoed it raw, and its stderr showed the forged line as a line of its own."""
    from tests.integration.conftest import TWO_MOCKS

    listen = f"tcp/127.0.0.1:{free_tcp_port()}"
    config = tmp_path / "cell.yaml"
    config.write_text(TWO_MOCKS, encoding="utf-8")
    forged = "FORGED ERROR"  # short: the daemon may shorten echoed client text
    daemon = subprocess.Popen(
        [sys.executable, "-m", "urdaemon", "serve", "--config", str(config), "--listen", listen],
        cwd=ROOT,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    stderr: list[str] = []
    drain_in_background(daemon, stderr)
    try:
        async with await Client.connect(listen, timeout=30.0) as client:
            alice = await client.robot("alice", timeout=30.0)
            token = (await alice.ensure_lease()).encode()  # the holder's goal is decoded, and logged
            body = {"positions": HOME, f"x\n{forged}\r": 1}
            reply = await client.request(alice.keys.goal_move, body, attachment=token)
            assert reply["accepted"] is False
    finally:
        daemon.send_signal(signal.SIGTERM)
        code = await asyncio.get_running_loop().run_in_executor(None, daemon.wait, 60)
    log = "".join(stderr)
    assert code == 0, log
    assert "FORGED" in log, log  # the warning was written, with the client's text in it
    assert not any(line.startswith(forged) for line in log.splitlines()), log
