"""Issue 13 finding 5: the callback links. A stray connection takes no link over, the loss of any one
link is noticed at once and repaired, forged tool-contact results are not published, refusals are
counted instead of logged one line each, and a callback port in use is one clear error."""

from __future__ import annotations

import asyncio
import logging
import time

import pytest

from tests.helpers import fake_address, free_tcp_port
from tests.ur.test_links_harness import program_is_running, ur_run
from urdaemon.backends.ur import servers as servers_module
from urdaemon.backends.ur.servers import CallbackServers
from urdaemon.errors import BackendError
from urdaemon.protocols import script_command

pytestmark = pytest.mark.timeout(90)

REFUSAL_LOG_EVERY: int = getattr(servers_module, "REFUSAL_LOG_EVERY", 100)
"""(read this way so that the test also runs, and fails, on the code before the fix)"""


class _Hooks:
    def __init__(self) -> None:
        self.links: list[tuple[str, bool, str]] = []

    def on_link(self, name: str, connected: bool, reason: str) -> None:
        self.links.append((name, connected, reason))

    def on_event(self, name: str, event: object) -> None:
        return


@pytest.mark.parametrize("port", ["reverse", "trajectory", "script_command"])
async def test_a_connection_from_the_robots_address_does_not_take_over_a_live_link(port: str) -> None:
    """Reproduction: with the program connected, open a TCP connection from the robot's own address to
    one of the callback ports, hold it and close it. Before the fix the daemon closed the program's
    link and took the stray one: the reverse socket's frames went to it and the goal aborted; on the
    trajectory or script-command port the robot then stayed ``ready`` without that link."""
    async with ur_run() as run:
        await run.until(lambda: program_is_running(run), what="the program holds every link")
        server = getattr(run.backend.servers, port)
        link = server.link
        programs = run.programs_sent
        reader, writer = await asyncio.open_connection(
            "127.0.0.1", server.port, local_addr=(run.fake.address, 0)
        )
        writer.write(b"\x00\x00\x00\x05")  # a forged int: it must reach nobody
        assert await asyncio.wait_for(reader.read(100), 10.0) == b"", "the stray connection is closed"
        writer.close()
        await run.cycles_pass(50)
        assert server.refused == 1
        assert server.link is link, "the program's link was kept"
        assert program_is_running(run)
        assert run.programs_sent == programs, "nothing had to be repaired"
        assert run.notices == [] or all(kind != "tool_contact" for kind, _ in run.notices)


@pytest.mark.parametrize("port", ["trajectory", "script_command"])
async def test_the_loss_of_one_link_is_noticed_at_once_and_repaired(port: str) -> None:
    """Reproduction: the program's trajectory (or script-command) link alone drops while the program
    runs on (its reverse socket still read). Before the fix the robot stayed ``ready: true`` (31 s+
    measured) while passthrough and script commands failed; the loss was never repaired."""
    async with ur_run() as run:
        await run.until(lambda: program_is_running(run), what="the program holds every link")
        programs = run.programs_sent
        server = getattr(run.backend.servers, port)
        assert server.link is not None
        server.link.close()
        await run.until(lambda: server.link is None, what="the link is gone")
        await run.cycles_pass(2)
        state = run.backend.state
        assert not run.ready, "not ready from the next cycle on"
        assert port in state.lifecycle_reason, state.lifecycle_reason
        # repaired: a new program brings every link back
        await run.until(lambda: program_is_running(run), what="the links are back")
        assert run.programs_sent > programs, "the program was sent again"
        assert run.backend.state.lifecycle_reason == ""


async def test_a_tool_contact_result_counts_only_when_armed() -> None:
    """Reproduction: a tool-contact result (an int on the script-command port) that no
    ``start_tool_contact`` asked for was published as a ``tool_contact`` event."""
    async with ur_run() as run:
        await run.until(lambda: program_is_running(run), what="the program holds every link")
        forged = script_command.ToolContactResult(script_command.ToolContactResultCode.SUCCESS)
        run.backend.on_event("script_command", forged)
        assert [kind for kind, _ in run.notices if kind == "tool_contact"] == []
        await run.backend.tool_contact(True)
        run.backend.on_event("script_command", forged)  # now it was asked for: one event
        run.backend.on_event("script_command", forged)  # and only one
        assert [text for kind, text in run.notices if kind == "tool_contact"] == ["contact"]


async def test_refused_connections_are_logged_with_a_count_not_one_line_each(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Reproduction: 250 connections to a callback port from an address that is not the robot. Before
    the fix each one logged a warning line (a stranger could fill the log without limit)."""
    hooks = _Hooks()
    ports = {name: free_tcp_port() for name in ("reverse", "script_sender", "trajectory", "script_command")}
    servers = CallbackServers(fake_address(), ports, hooks)
    await servers.start("127.0.0.1")
    caplog.set_level(logging.INFO, logger="urdaemon.ur")
    try:
        total = 2 * REFUSAL_LOG_EVERY + 50
        for _ in range(total):
            reader, writer = await asyncio.open_connection("127.0.0.1", ports["reverse"])
            assert await asyncio.wait_for(reader.read(10), 10.0) == b""
            writer.close()
        assert servers.reverse.refused == total
        lines = [r.getMessage() for r in caplog.records if "refused" in r.getMessage()]
        assert len(lines) == 3, lines  # the first, the 100th and the 200th
        assert f"{2 * REFUSAL_LOG_EVERY} refused so far" in lines[-1]
        assert hooks.links == []
    finally:
        await servers.close()


async def test_a_callback_port_in_use_is_one_clear_error() -> None:
    """Reproduction: another program listens on the robot's reverse port. Before the fix
    ``servers.start`` raised a bare OSError, which the runtime logged with a traceback every retry."""
    holder = await asyncio.start_server(lambda r, w: None, "127.0.0.1", 0)
    port = holder.sockets[0].getsockname()[1]
    ports = {
        "reverse": port,
        "script_sender": free_tcp_port(),
        "trajectory": free_tcp_port(),
        "script_command": free_tcp_port(),
    }
    servers = CallbackServers(fake_address(), ports, _Hooks())
    try:
        with pytest.raises(BackendError) as raised:
            await servers.start("127.0.0.1")
        text = str(raised.value)
        assert f"reverse callback port 127.0.0.1:{port}" in text
        assert "in use" in text
        assert "\n" not in text
        # nothing it opened before the failure stays open
        assert all(server._server is None or not server._server.is_serving() for server in servers.all)
    finally:
        await servers.close()
        holder.close()
        await holder.wait_closed()


async def test_the_script_sender_hands_the_program_only_to_the_robot() -> None:
    """``request_program`` from an address that is not the robot's gets nothing (closed at once).
    This held before issue 13 too; kept as the guard of the rule docs/ursim.md states."""
    async with ur_run() as run:
        await run.until(lambda: program_is_running(run), what="the program holds every link")
        port = run.backend.servers.script_sender.port
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(b"request_program\n")
        assert await asyncio.wait_for(reader.read(100), 10.0) == b""
        writer.close()
        assert run.backend.servers.script_sender.refused == 1


async def test_a_program_request_on_a_headless_robot_opens_no_way_to_take_over_a_link() -> None:
    """Reproduction (review of issue 13): with the headless program holding every link, a process on
    the robot's address sent ``request_program`` on the script-sender port, which opened the window
    in which a new program's connections may replace the live ones; its next connection to the reverse
    port then took the live link over and received the reverse frames."""
    async with ur_run() as run:
        await run.until(lambda: program_is_running(run), what="the program holds every link")
        servers = run.backend.servers
        live = servers.reverse.link
        reader, writer = await asyncio.open_connection(
            "127.0.0.1", servers.script_sender.port, local_addr=(run.fake.address, 0)
        )
        writer.write(b"request_program\n")
        await writer.drain()
        assert await asyncio.wait_for(reader.readuntil(b"end\n"), 10.0), "the script is handed out"
        writer.close()
        stray_reader, stray = await asyncio.open_connection(
            "127.0.0.1", servers.reverse.port, local_addr=(run.fake.address, 0)
        )
        assert await asyncio.wait_for(stray_reader.read(100), 10.0) == b"", "the stray is closed"
        stray.close()
        await run.cycles_pass(20)
        assert servers.reverse.refused == 1
        assert servers.reverse.link is live
        assert program_is_running(run)


async def test_a_stray_that_connects_before_the_new_program_is_replaced_by_it() -> None:
    """Reproduction (review of issue 13): right after the daemon sent a new program, a stray
    connection from the robot's address reached the trajectory port first and used up the one
    replacement the window allowed; the program's own connection was then refused and the robot
    stayed without its trajectory link. Within the window the newest connection now wins, and the
    window closes once the new program holds every link."""
    async with ur_run() as run:
        await run.until(lambda: program_is_running(run), what="the program holds every link")
        servers = run.backend.servers
        primary = run.backend.links.primary
        assert primary is not None
        send_script = primary.send_script
        held: list[str] = []
        primary.send_script = held.append  # type: ignore[method-assign,assignment]
        program_link = servers.trajectory.link
        sent_at = time.monotonic()
        await run.backend.resend_program()
        assert len(held) == 1
        _, stray = await asyncio.open_connection(
            "127.0.0.1", servers.trajectory.port, local_addr=(run.fake.address, 0)
        )
        await run.until(
            lambda: servers.trajectory.link is not program_link, what="the stray holds the trajectory port"
        )
        stray_link = servers.trajectory.link
        send_script(held[0])
        await run.until(
            lambda: run.backend.links.program.links_up_at > sent_at and program_is_running(run),
            timeout=30.0,
            what="the new program holds every link, the stray replaced",
        )
        assert servers.trajectory.link is not stray_link
        stray.close()
        # the window is closed: one more stray is refused
        refused = servers.trajectory.refused
        reader, late = await asyncio.open_connection(
            "127.0.0.1", servers.trajectory.port, local_addr=(run.fake.address, 0)
        )
        assert await asyncio.wait_for(reader.read(100), 10.0) == b""
        late.close()
        assert servers.trajectory.refused == refused + 1
        assert program_is_running(run)
