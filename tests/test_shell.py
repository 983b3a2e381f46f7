"""The asyncio shell every socket uses (``urdaemon.shell``): a codec over a real socket on 127.0.0.1,
driven by a plain client; waits on events only."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import pytest

from urdaemon.errors import ConnectionLostError, RemoteProtocolError
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import rtde
from urdaemon.protocols._buffer import Side
from urdaemon.shell import Shell, connect, serve

pytestmark = pytest.mark.timeout(30)

WAIT_S = 5.0


class Served:
    """The server's side: the shells it made, their events and the reasons they ended."""

    def __init__(self) -> None:
        self.shells: list[Shell] = []
        self.events: asyncio.Queue[Any] = asyncio.Queue()
        self.reasons: list[Exception] = []
        self.ended = asyncio.Event()

    def make(self, codec: Any, on_event: Any = None, **options: Any) -> Shell:
        handler = self.events.put_nowait if on_event is None else on_event
        shell = Shell(codec, "test", handler, on_close=self._ended, **options)
        self.shells.append(shell)
        return shell

    def _ended(self, reason: Exception) -> None:
        self.reasons.append(reason)
        self.ended.set()

    async def next(self) -> Any:
        return await asyncio.wait_for(self.events.get(), WAIT_S)


@asynccontextmanager
async def served(
    codec: Any, **options: Any
) -> AsyncIterator[tuple[Served, asyncio.StreamReader, asyncio.StreamWriter]]:
    """A server of ``codec`` shells on 127.0.0.1 (an OS port) and one plain client connected to it."""
    side = Served()
    server = await serve(lambda: side.make(codec(), **options), "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        yield side, reader, writer
    finally:
        writer.close()
        server.close()
        await server.wait_closed()


def _dashboard() -> dash.DashboardConnection:
    return dash.DashboardConnection(Side.ROBOT)


def _rtde() -> rtde.RtdeConnection:
    return rtde.RtdeConnection(Side.ROBOT)


async def test_events_arrive_in_order_and_a_split_message_is_joined() -> None:
    async with served(_dashboard) as (side, _, writer):
        writer.write(b"power on\nbrake rel")
        await writer.drain()
        first = await side.next()
        assert isinstance(first, dash.CommandReceived)
        assert isinstance(first.command, dash.PowerOn)
        writer.write(b"ease\nrobotmode\n")
        second, third = await side.next(), await side.next()
        assert isinstance(second.command, dash.BrakeRelease)
        assert isinstance(third.command, dash.GetRobotMode)
        assert side.reasons == []


async def test_a_reply_is_written_and_the_peer_reads_it() -> None:
    async with served(_dashboard) as (side, reader, writer):
        writer.write(b"robotmode\n")
        await side.next()
        side.shells[0].send(dash.Banner())
        side.shells[0].send(dash.ReplyLine("Robotmode: RUNNING"))
        await asyncio.wait_for(reader.readline(), WAIT_S)  # the banner
        assert await asyncio.wait_for(reader.readline(), WAIT_S) == b"Robotmode: RUNNING\n"


async def test_a_bad_frame_closes_the_connection_with_the_codecs_error() -> None:
    """An RTDE package whose size is smaller than its header: the codec's error ends the connection."""
    async with served(_rtde) as (side, reader, writer):
        writer.write(b"\x00\x01V")
        await asyncio.wait_for(side.ended.wait(), WAIT_S)
        assert len(side.reasons) == 1
        reason = side.reasons[0]
        assert isinstance(reason, RemoteProtocolError)
        assert str(reason).startswith("rtde: ")
        assert side.shells[0].closed.result() is reason
        assert await asyncio.wait_for(reader.read(), WAIT_S) == b""  # the shell closed the socket


async def test_send_after_close_is_refused() -> None:
    async with served(_dashboard) as (side, reader, writer):
        writer.write(b"robotmode\n")
        await side.next()
        shell = side.shells[0]
        shell.close()
        await asyncio.wait_for(side.ended.wait(), WAIT_S)
        with pytest.raises(ConnectionLostError, match="test: not sent, the connection has ended"):
            shell.send(dash.ReplyLine("too late"))
        assert await asyncio.wait_for(reader.read(), WAIT_S) == b""


async def test_a_lost_connection_is_reported_once() -> None:
    async with served(_dashboard) as (side, _, writer):
        writer.write(b"robotmode\n")
        await side.next()
        writer.close()
        await asyncio.wait_for(side.ended.wait(), WAIT_S)
        shell = side.shells[0]
        shell.close()
        shell.connection_lost(None)  # a second report changes nothing
        assert [str(r) for r in side.reasons] == ["test: connection closed by the robot"]
        assert isinstance(side.reasons[0], ConnectionLostError)


async def test_an_awaitable_handler_holds_back_the_rest_of_the_read_in_order() -> None:
    """A handler that answers later (the fake's dashboard): the events after it wait for it, and so
    do later reads."""
    order: list[str] = []
    started, gate, done = asyncio.Event(), asyncio.Event(), asyncio.Event()

    async def slow(line: str) -> None:
        started.set()
        await gate.wait()
        order.append(line)

    def on_event(event: Any) -> Any:
        if event.line == "robotmode":
            return slow(event.line)
        order.append(event.line)
        if len(order) == 4:
            done.set()
        return None

    async with served(_dashboard, on_event=on_event) as (_, _, writer):
        writer.write(b"power on\nrobotmode\nbrake release\n")
        await writer.drain()
        await asyncio.wait_for(started.wait(), WAIT_S)
        writer.write(b"power off\n")
        await writer.drain()
        for _ in range(50):  # the loop turns; nothing after the held event is handled meanwhile
            await asyncio.sleep(0)
        assert order == ["power on"]
        gate.set()
        await asyncio.wait_for(done.wait(), WAIT_S)
        assert order == ["power on", "robotmode", "brake release", "power off"]


async def test_a_long_read_is_decoded_a_chunk_per_turn_in_order() -> None:
    lines = [f"load /programs/p{i:03}.urp" for i in range(200)]
    async with served(_dashboard, chunk=256) as (side, _, writer):
        writer.write("".join(f"{line}\n" for line in lines).encode())
        await writer.drain()
        got = [(await side.next()).line for _ in lines]
        assert got == lines


async def test_connect_names_the_link_when_nobody_listens() -> None:
    server = await serve(lambda: Shell(_dashboard(), "x"), "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    server.close()
    await server.wait_closed()
    with pytest.raises(ConnectionLostError, match=f"probe: cannot connect to 127.0.0.1:{port}"):
        await connect(lambda: Shell(_dashboard(), "probe"), "127.0.0.1", port, timeout=WAIT_S, name="probe")


async def test_a_handler_that_raises_ends_the_connection_with_its_error() -> None:
    """A handler's bug (here a KeyError) on the direct path ends the connection with that error named
    and reported to the loop's exception handler, as on the deferred path. Reproduction on the old code:
    ``handle`` caught only ProtocolError and ConnectionError, so the KeyError escaped
    ``data_received``; asyncio logged "Fatal error" and the shell ended with ``connection lost: 'x'``."""
    bug = KeyError("x")
    reported: list[dict[str, Any]] = []
    loop = asyncio.get_running_loop()
    previous = loop.get_exception_handler()
    loop.set_exception_handler(lambda _, context: reported.append(context))

    def on_event(event: Any) -> None:
        raise bug

    try:
        async with served(_dashboard, on_event=on_event) as (side, reader, writer):
            writer.write(b"robotmode\n")
            await asyncio.wait_for(side.ended.wait(), WAIT_S)
            assert side.reasons == [bug]
            assert side.shells[0].closed.result() is bug
            assert await asyncio.wait_for(reader.read(), WAIT_S) == b""  # the shell closed the socket
    finally:
        loop.set_exception_handler(previous)
    assert [context.get("exception") for context in reported] == [bug]
    assert reported[0]["message"] == "test: an event handler failed"


async def test_a_cancellation_that_lands_as_the_connection_completes_is_not_lost(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A supervisor stopped while its backend dials must stop: Python 3.11's ``wait_for`` returned the
    connection instead when the cancellation and the connection arrived in the same step."""
    loop = asyncio.get_running_loop()
    dialing: list[asyncio.Task[Any]] = []
    made: list[Any] = []

    async def completes_as_it_is_cancelled(factory: Any, *args: Any, **kwargs: Any) -> tuple[None, Any]:
        dialing[0].cancel()  # the caller is cancelled in the very step the connection completes
        made.append(factory())
        return None, made[-1]

    monkeypatch.setattr(loop, "create_connection", completes_as_it_is_cancelled)
    dialing.append(asyncio.create_task(connect(object, "127.0.0.1", 1, timeout=5.0, name="probe")))
    with pytest.raises(asyncio.CancelledError):
        await dialing[0]
    assert len(made) == 1
