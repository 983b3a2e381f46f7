"""The External Control URCap's script fetch runs on the one shell, with the script sender's codec (issue 15).

Reproduction: ``Programs.play_urcap`` opened its own ``asyncio.open_connection`` stream and wrote the
request bytes itself; ``ScriptFetch`` did not exist, so these tests fail to import on that code.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager

from urdaemon.fakeur.programs import ScriptFetch
from urdaemon.protocols import script_sender
from urdaemon.shell import Shell, connect

SCRIPT = "def fetched():\n  sync()\nend\n"

Handler = Callable[[asyncio.StreamReader, asyncio.StreamWriter], Awaitable[None]]


@asynccontextmanager
async def _daemon(handler: Handler) -> AsyncIterator[int]:
    """A stand-in for the daemon's script sender on a port the OS picks."""
    server = await asyncio.start_server(handler, "127.0.0.1", 0)
    try:
        yield server.sockets[0].getsockname()[1]
    finally:
        server.close()
        await server.wait_closed()


async def _fetch(port: int) -> str:
    fetch = await connect(ScriptFetch, "127.0.0.1", port, timeout=5.0, name="urcap")
    try:
        return await asyncio.wait_for(fetch.program(), 10.0)
    finally:
        fetch.close()


async def test_the_fetch_is_a_shell_that_asks_once_and_takes_the_whole_script() -> None:
    """The daemon answers and keeps the connection open: the URCap stops reading once no more lines
    come (URCAP_MORE_S) and runs the text as sent, newline included."""
    requests: list[bytes] = []
    done = asyncio.Event()

    async def answer(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        requests.append(await reader.readline())
        writer.write(SCRIPT.encode())
        await writer.drain()
        await reader.read()  # until the URCap closes
        writer.close()
        done.set()

    async with _daemon(answer) as port:
        assert issubclass(ScriptFetch, Shell)
        assert await _fetch(port) == SCRIPT
        await asyncio.wait_for(done.wait(), 10.0)
    assert requests == [script_sender.REQUEST_LINE]


async def test_a_script_cut_off_by_the_daemon_closing_is_taken_as_it_came() -> None:
    """The daemon closes after a last line without its newline: the text is what arrived, as before."""

    async def answer(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await reader.readline()
        writer.write(b"def cut():\n  sync()")
        await writer.drain()
        writer.close()

    async with _daemon(answer) as port:
        assert await _fetch(port) == "def cut():\n  sync()"
