"""The callback servers against the fake controller running a program, headless and in URCap mode."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from tests.helpers import fake_address, free_tcp_port
from urdaemon.backends.ur.servers import CallbackServers
from urdaemon.fakeur.controller import FakeController
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import primary as prim
from urdaemon.protocols import reverse, script_command, script_sender
from urdaemon.protocols._buffer import Side
from urdaemon.urscript import ScriptParameters, render_control_script

pytestmark = pytest.mark.timeout(60)


class Hooks:
    """Records what the servers report and wakes waiters."""

    def __init__(self) -> None:
        self.links: list[tuple[str, bool, str]] = []
        self.events: list[tuple[str, Any]] = []
        self.changed = asyncio.Event()
        self.program = ""
        self.servers: CallbackServers | None = None

    def on_link(self, name: str, connected: bool, reason: str) -> None:
        self.links.append((name, connected, reason))
        self.changed.set()

    def on_event(self, name: str, event: Any) -> None:
        self.events.append((name, event))
        if isinstance(event, script_sender.ProgramRequested) and self.servers is not None:
            self.servers.script_sender.send(script_sender.Program(self.program))
        self.changed.set()

    async def wait_for(self, predicate: Any, timeout: float = 10.0) -> None:
        async with asyncio.timeout(timeout):
            while not predicate():
                self.changed.clear()
                await self.changed.wait()


def _ports() -> dict[str, int]:
    return {name: free_tcp_port() for name in ("reverse", "script_sender", "trajectory", "script_command")}


def _program(ports: dict[str, int]) -> str:
    """Our control script, dialling these servers back (the fake runs it as a controller would)."""
    return render_control_script(
        ScriptParameters(
            "127.0.0.1",
            reverse_port=ports["reverse"],
            trajectory_port=ports["trajectory"],
            script_command_port=ports["script_command"],
        )
    )


def _connected(hooks: Hooks, names: set[str]) -> bool:
    state: dict[str, bool] = {}
    for name, up, _ in hooks.links:
        state[name] = up
    return all(state.get(n) for n in names)


async def test_a_headless_program_connects_back_and_the_daemon_drives_the_arm() -> None:
    fake = FakeController("ur10e", address=fake_address(), powered=True)
    await fake.start()
    hooks = Hooks()
    ports = _ports()
    servers = CallbackServers(fake.address, ports, hooks)
    await servers.start("127.0.0.1")
    try:
        _, writer = await asyncio.open_connection(fake.address, 30001)
        conn = prim.PrimaryConnection(Side.DAEMON)
        conn.send(prim.Script(prim.headless_program(_program(ports))))
        writer.write(conn.data_to_send())
        callback = {"reverse", "trajectory", "script_command"}
        await hooks.wait_for(lambda: _connected(hooks, callback))
        assert all(reason.endswith(f"from {fake.address}") for _, up, reason in hooks.links if up)
        start = fake.arm.q[0]
        target = (start + 0.02, *fake.arm.q[1:])
        # a daemon streams one frame per robot cycle; servoj's gain and lookahead make the arm settle on
        # the held target in about 0.3 s (0.03 / 2000), not reach it in one cycle
        for _ in range(2500):
            assert servers.reverse.send(reverse.ServoJ(target, 0.1))
            await fake.cycles_pass(1)
            if abs(fake.arm.q[0] - target[0]) < 1e-9:
                break
        assert fake.arm.q[0] == pytest.approx(target[0], abs=1e-9)
        assert servers.script_command.send(script_command.SetPayload(2.5, (0.0, 0.0, 0.1)))
        # the program reads its script_command socket in its cycle: a few cycles after it arrives
        await fake.until(lambda: fake.arm.payload_mass == 2.5, cycles=500)
        assert fake.arm.payload_mass == 2.5
        servers.reverse.send(reverse.Stopped())
        await hooks.wait_for(lambda: not servers.reverse.connected)
        assert not servers.trajectory.connected
        writer.close()
    finally:
        await servers.close()
        await fake.close()


async def test_connections_from_another_address_are_refused_and_a_live_link_is_kept() -> None:
    """A stranger is closed at once; a second connection from the robot's address while the first is
    live is refused too (it would take the program's link over), unless a new program was started."""
    robot = fake_address()
    hooks = Hooks()
    ports = _ports()
    servers = CallbackServers(robot, ports, hooks)
    await servers.start("127.0.0.1")
    try:
        reader, writer = await asyncio.open_connection("127.0.0.1", ports["reverse"])
        assert await asyncio.wait_for(reader.read(10), 5.0) == b"", "a stranger is closed at once"
        writer.close()
        assert servers.reverse.refused == 1
        assert hooks.links == []
        _, w1 = await asyncio.open_connection("127.0.0.1", ports["reverse"], local_addr=(robot, 0))
        await hooks.wait_for(lambda: servers.reverse.connected)
        first_link = servers.reverse.link
        r2, w2 = await asyncio.open_connection("127.0.0.1", ports["reverse"], local_addr=(robot, 0))
        assert await asyncio.wait_for(r2.read(10), 5.0) == b"", "the second connection is closed"
        assert servers.reverse.refused == 2
        assert servers.reverse.link is first_link
        w2.close()
        servers.expect_program()  # a new program may replace the old one's link
        _, w3 = await asyncio.open_connection("127.0.0.1", ports["reverse"], local_addr=(robot, 0))
        await hooks.wait_for(lambda: servers.reverse.link is not first_link and servers.reverse.connected)
        assert servers.reverse.refused == 2, "the new program's connection was accepted"
        w3.close()
        await hooks.wait_for(lambda: not servers.reverse.connected)
        w1.close()
    finally:
        await servers.close()


async def test_urcap_mode_play_fetches_the_program_from_the_script_sender() -> None:
    hooks = Hooks()
    ports = _ports()
    hooks.program = _program(ports)
    address = fake_address()
    servers = CallbackServers(address, ports, hooks)
    hooks.servers = servers
    await servers.start("127.0.0.1")
    fake = FakeController("ur10e", address=address, powered=True, urcap=("127.0.0.1", ports["script_sender"]))
    await fake.start()
    try:
        reader, writer = await asyncio.open_connection(fake.address, 29999)
        conn = dash.DashboardConnection(Side.DAEMON)
        conn.receive_data(await reader.readline())
        conn.send(dash.Play())
        writer.write(conn.data_to_send())
        (reply,) = conn.receive_data(await asyncio.wait_for(reader.readline(), 5.0))
        assert isinstance(reply, dash.CommandReply)
        assert reply.success, reply.text
        await hooks.wait_for(lambda: _connected(hooks, {"reverse", "trajectory", "script_command"}))
        assert any(isinstance(e, script_sender.ProgramRequested) for _, e in hooks.events)
        writer.close()
    finally:
        await fake.close()
        await servers.close()
