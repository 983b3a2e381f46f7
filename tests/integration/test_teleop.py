"""``urdaemon teleop`` driven through a real terminal: tmux runs it against a daemon in the test's loop
(the mock backend), ``send-keys`` types into it, and the robot's own messages say what happened.

Reproduction on the code before issue 17: there was no ``teleop`` command (``urdaemon teleop`` was
a usage error, exit 2) and no ``urdaemon.teleop``, so every test here fails.
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import secrets
import shlex
import shutil
import subprocess
import sys
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager

import pytest

from tests.helpers import free_tcp_port, run_cli_in_thread
from tests.integration.conftest import ROOT, running_daemon
from urdaemon.client import RobotClient, Subscription
from urdaemon.teleop_keys import rotation_vector

pytestmark = pytest.mark.timeout(120)

TMUX = shutil.which("tmux")
needs_tmux = pytest.mark.skipif(TMUX is None, reason="tmux is not installed: teleop needs a real terminal")

CELL = """
cell: telecell
robots:
  - name: alice
    model: ur10e
    backend: mock
    pose: {xyz: [0.5, 0.0, 0.0]}
    mock: {initial_positions: [0.3, -1.8, 1.6, -1.4, -1.5708, 0.2]}
    motion: {stream_timeout: 0.5}
"""
"""alice away from every singularity. Her deadman (0.5 s) is longer than teleop's release
(``RELEASE_S``, 0.15 s, then zero twists): what stops her when the keys stop is teleop's own
Cartesian brake, along the line, the behaviour under test. A shorter deadman fired whenever the
teleop process stalled for 0.1 s on a loaded machine, and its joint-space brake curved the path
(6.3 mm along +y with 0.9 mm across); tests/integration/test_cartesian.py tests that brake."""
WAIT_S = 20.0
"""Bound of every wait for one message."""
STATES_PER_POLL = 25
"""Joint states (50 ms at 500 Hz) between two looks at the terminal: the robot's clock paces them."""
MAX_POLLS = 400
"""At most this many looks (20 s of joint states) for anything the terminal or the robot must show."""
KEYS_PER_BURST = 3
STATES_PER_KEY = 10
"""A key every 10 joint states (20 ms): faster than a terminal's auto-repeat, within RELEASE_S."""
MAX_KEYS = 1500
MOVED_M = 0.005
"""How far the TCP must go in +y before the keys stop."""


class Tmux:
    """A tmux server on a private socket with one session running ``command``; killed on close."""

    def __init__(self, command: str) -> None:
        assert TMUX is not None
        self.base = [TMUX, "-L", f"urdaemon-test-{os.getpid()}-{secrets.token_hex(4)}", "-f", "/dev/null"]
        self.command = command

    async def run(self, *args: str) -> str:
        done = await asyncio.to_thread(
            subprocess.run, [*self.base, *args], capture_output=True, text=True, timeout=30, check=False
        )
        assert done.returncode == 0, f"tmux {' '.join(args)}: {done.stderr}"
        return done.stdout

    async def start(self) -> None:
        env = f"PYTHONPATH={shlex.quote(str(ROOT))}"
        await self.run("new-session", "-d", "-s", "t", "-x", "220", "-y", "30", f"env {env} {self.command}")

    async def screen(self) -> str:
        return await self.run("capture-pane", "-p", "-t", "t")

    async def keys(self, *keys: str) -> None:
        await self.run("send-keys", "-t", "t", *keys)

    def kill(self) -> None:
        subprocess.run([*self.base, "kill-server"], capture_output=True, timeout=30, check=False)


@asynccontextmanager
async def teleop_in_tmux(endpoint: str) -> AsyncIterator[Tmux]:
    """``urdaemon teleop alice`` in a tmux terminal; afterwards the shell prints, in one line, its
    exit code and whether the terminal is back in canonical mode with echo (``stty``), and waits."""
    teleop = f"{shlex.quote(sys.executable)} -m urdaemon teleop alice --connect {endpoint} --speed 0.1"
    modes = "stty -a | tr ' ;' '\\n\\n' | grep -x -e icanon -e -icanon -e echo -e -echo | tr '\\n' ' '"
    script = f'{teleop}; code=$?; modes=$({modes}); echo "teleop exited $code, modes: $modes."; sleep 120'

    tmux = Tmux(f"sh -c {shlex.quote(script)}")
    try:
        await tmux.start()
        yield tmux
    finally:
        tmux.kill()


def _exit_line(screen: str) -> str | None:
    """The shell's line after teleop ended (exit code, terminal modes), once it is complete."""
    for line in screen.splitlines():
        if line.startswith("teleop exited") and line.rstrip().endswith("."):
            return line.rstrip()
    return None


async def _until(states: Subscription, check: Callable[[], object], what: str) -> None:
    """Wait, paced by alice's joint states, until ``check()`` (awaited if it is a coroutine) is true."""
    for _ in range(MAX_POLLS):
        outcome = check()
        if asyncio.iscoroutine(outcome):
            outcome = await outcome
        if outcome:
            return
        for _ in range(STATES_PER_POLL):
            await states.get(timeout=WAIT_S)
    raise AssertionError(f"not within {MAX_POLLS} looks: {what}")


async def _tcp_pose(alice: RobotClient) -> list[float]:
    sub = alice.client.subscribe(alice.keys.tcp_pose, 10)
    try:
        message = await sub.get_json(WAIT_S)
    finally:
        alice.client.unsubscribe(sub)
    return [*message["position"], *rotation_vector(message["orientation"])]


@needs_tmux
async def test_teleop_in_a_terminal_moves_on_w_and_stops_when_the_keys_stop() -> None:
    async with running_daemon(CELL) as (daemon, client):
        alice = await client.robot("alice")
        states = alice.joint_states(100_000)
        start = await _tcp_pose(alice)
        async with teleop_in_tmux(daemon.listen_endpoints[0]) as tmux:

            async def line_shown() -> bool:
                return "frame base" in await tmux.screen()

            await _until(states, line_shown, "teleop's live line")
            assert await alice.lease_info() is not None, "teleop holds alice's lease"
            moved = False
            for _ in range(MAX_KEYS // KEYS_PER_BURST):  # a held key: its auto-repeat, w after w
                await tmux.keys(*["w"] * KEYS_PER_BURST)
                for _ in range(STATES_PER_KEY):
                    await states.get(timeout=WAIT_S)
                now = await _tcp_pose(alice)
                if now[1] - start[1] > MOVED_M:
                    moved = True
                    break
            assert moved, f"the TCP did not move {MOVED_M} m in +y: {start} -> {now}"
            # no more keys: the twist goes to zero within RELEASE_S, the robot comes to rest
            for _ in range(5000):  # at most 10 s of joint states
                sample = json.loads((await states.get(timeout=WAIT_S))[1])
                if all(v == 0.0 for v in sample["velocity"]):
                    break
            else:
                raise AssertionError("alice still moves 10 s after the last key")
            rest = await _tcp_pose(alice)
            travel = [b - a for a, b in zip(start[:3], rest[:3], strict=True)]
            assert travel[1] > MOVED_M, travel
            assert math.hypot(travel[0], travel[2]) < 0.1 * travel[1], f"along +y only: {travel}"
            screen = await tmux.screen()
            assert "alice: x " in screen, screen
            assert "0.100 m/s" in screen, screen
            await tmux.keys("x")

            async def exited() -> bool:
                return _exit_line(await tmux.screen()) is not None

            await _until(states, exited, "teleop's exit after x")
            assert _exit_line(await tmux.screen()) == "teleop exited 0, modes: icanon echo ."
        assert await alice.lease_info() is None, "teleop released alice's lease when it quit"


@needs_tmux
async def test_ctrl_c_quits_teleop_and_puts_the_terminal_back() -> None:
    async with running_daemon(CELL) as (daemon, client):
        alice = await client.robot("alice")
        states = alice.joint_states(100_000)
        async with teleop_in_tmux(daemon.listen_endpoints[0]) as tmux:

            async def line_shown() -> bool:
                return "frame base" in await tmux.screen()

            await _until(states, line_shown, "teleop's live line")
            await tmux.keys("b", "i")  # the tool frame, 0.125 m/s: the line says so

            async def changed() -> bool:
                screen = await tmux.screen()
                return "frame tool" in screen and "0.125 m/s" in screen

            await _until(states, changed, "the frame and speed keys on the line")
            await tmux.keys("C-c")

            async def exited() -> bool:
                return _exit_line(await tmux.screen()) is not None

            await _until(states, exited, "teleop's exit after Ctrl-C")
            assert _exit_line(await tmux.screen()) == "teleop exited 0, modes: icanon echo ."


async def test_teleop_without_a_terminal_is_refused() -> None:
    nobody = f"tcp/127.0.0.1:{free_tcp_port()}"
    run = await run_cli_in_thread("teleop", "alice", "--connect", nobody, timeout=30)
    assert run.code == 2, run
    assert "teleop reads keys from a terminal" in run.stderr
    run = await run_cli_in_thread("teleop", "alice", "--speed", "5", "--connect", nobody, timeout=30)
    assert run.code == 2, run
    assert "--speed must be within" in run.stderr


def test_raw_terminal_is_put_back_when_the_block_fails() -> None:
    import termios

    from urdaemon.teleop import raw_terminal

    leader, follower = os.openpty()
    inside: list[int] = []

    def fail_in_raw_mode() -> None:
        with raw_terminal(follower):
            inside.append(termios.tcgetattr(follower)[3])
            raise RuntimeError("boom")

    try:
        before = termios.tcgetattr(follower)
        with pytest.raises(RuntimeError, match="boom"):
            fail_in_raw_mode()
        assert not inside[0] & termios.ICANON, "raw inside the block"
        assert termios.tcgetattr(follower) == before, "put back after it failed"
    finally:
        os.close(leader)
        os.close(follower)
