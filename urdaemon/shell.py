"""The one asyncio shell around a sans-IO codec: every socket of the daemon and the fake goes through it.

A ``Shell`` is an ``asyncio.Protocol`` that owns one codec (``urdaemon.protocols``): bytes received go
to ``codec.receive_data``, each event to the owner's ``on_event`` in order, and what the codec queued
is written out (``transmit``, a hook the fake overrides to apply its faults). ``send(message)``
encodes and writes at once. The connection ends once, with a reason (``closed`` and ``on_close``): a
``ConnectionLostError`` naming the shell (``<name>: connection lost: …`` or ``<name>: connection
closed by the <peer_name>``), the codec's own ``ProtocolError`` when the peer sent bad bytes, or the
error an event handler raised (one that is not a protocol or connection error is also handed to the
loop's exception handler); either closes the socket. After that ``send`` is refused.

For servers that answer requests (the fake's), a handler may return an awaitable: the shell stops
reading until it is done and hands the rest of the read over in order afterwards. ``chunk`` caps the
bytes decoded per loop turn (a flood of requests is taken a chunk at a time), and ``paced`` stops
reading a peer that does not read its replies (TCP flow control holds it back).

No codec takes the time or asks for a timer today, so the shell passes no ``now`` and arms no timer;
a codec that needs one would get it here. ``connect`` and ``serve`` open a shell's connection or
listen for them, on the host given.
"""

from __future__ import annotations

import asyncio
import contextlib
import inspect
import socket
from collections.abc import Awaitable, Callable
from typing import Any, Protocol, TypeVar, cast

from urdaemon.errors import ConnectionLostError, ProtocolError, UrTimeoutError

__all__ = ["Codec", "Shell", "connect", "serve"]

_S = TypeVar("_S", bound="Shell")


class Codec(Protocol):
    """What the shell needs of a codec (every ``urdaemon.protocols`` connection has it)."""

    def receive_data(self, data: bytes) -> list[Any]: ...
    def send(self, message: Any) -> None: ...
    def data_to_send(self) -> bytes: ...


def _ignore(event: Any) -> None:
    return None


class Shell(asyncio.Protocol):
    """One codec over one socket."""

    def __init__(
        self,
        codec: Any,
        name: str,
        on_event: Callable[[Any], Awaitable[Any] | None] = _ignore,
        *,
        on_close: Callable[[Exception], None] | None = None,
        peer_name: str = "robot",
        chunk: int = 0,
        paced: bool = False,
        keepalive: bool = False,
    ) -> None:
        self.codec = codec
        self.name = name
        self.on_event = on_event
        self.on_close = on_close
        self.peer_name = peer_name
        """Who is on the other end, for ``connection closed by the <peer_name>``."""
        self.chunk = chunk
        """At most this many bytes decoded per loop turn (0: a whole read at once)."""
        self.paced = paced
        self.keepalive = keepalive
        self.transport: asyncio.Transport | None = None
        self.closed: asyncio.Future[Exception] = asyncio.get_running_loop().create_future()
        """The reason the connection ended, once it has."""
        self._backlog = b""
        self._work: asyncio.Task[None] | None = None
        self._writable: asyncio.Future[None] | None = None

    # ---- the connection ------------------------------------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # uvloop's transports are not asyncio.Transport subclasses but offer the same methods
        self.transport = cast(asyncio.Transport, transport)
        if not self.opened():
            transport.close()
            return
        sock = transport.get_extra_info("socket")
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                if self.keepalive:
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)

    def opened(self) -> bool:
        """Whether to keep a connection just made (a subclass refuses one by returning False)."""
        return True

    def connection_lost(self, exc: Exception | None) -> None:
        how = f"connection lost: {exc}" if exc else f"connection closed by the {self.peer_name}"
        self.end(ConnectionLostError(f"{self.name}: {how}"))
        if self._work is not None:
            self._work.cancel()
        if self._writable is not None and not self._writable.done():
            self._writable.set_result(None)

    def end(self, reason: Exception) -> None:
        """The connection ended for ``reason``: told once, to ``closed`` and ``on_close``."""
        if self.closed.done():
            return
        self.closed.set_result(reason)
        if self.on_close is not None:
            self.on_close(reason)

    def fail(self, error: Exception) -> None:
        """End with ``error`` and close the socket."""
        self.end(error)
        self.close()

    def close(self) -> None:
        """Close the connection (``connection_lost`` reports it)."""
        if self.transport is not None:
            self.transport.close()

    def is_closing(self) -> bool:
        """True once the connection is closed or closing."""
        return self.transport is None or self.transport.is_closing()

    # ---- sending ----------------------------------------------------------------------------------------

    def send(self, message: Any) -> None:
        """Encode ``message`` and write it now; ConnectionLostError once the connection has ended."""
        if self.closed.done():
            raise ConnectionLostError(f"{self.name}: not sent, the connection has ended")
        self.codec.send(message)
        self.flush()

    def flush(self) -> None:
        """Write out what the codec has queued."""
        data = self.codec.data_to_send()
        if data:
            self.transmit(data)

    def transmit(self, data: bytes) -> None:
        """Where encoded bytes go (a hook: the fake applies its faults here)."""
        self.write(data)

    def write(self, data: bytes) -> None:
        """Write bytes to the socket as they are (dropped once it is closing)."""
        transport = self.transport
        if transport is not None and not transport.is_closing():
            transport.write(data)

    def pause_writing(self) -> None:
        if self._writable is None or self._writable.done():
            self._writable = asyncio.get_running_loop().create_future()

    def resume_writing(self) -> None:
        if self._writable is not None and not self._writable.done():
            self._writable.set_result(None)

    async def drain(self) -> None:
        """Wait while the peer does not read what was written (the transport's buffer is full)."""
        if self._writable is not None and not self._writable.done():
            await self._writable

    # ---- receiving --------------------------------------------------------------------------------------

    def data_received(self, data: bytes) -> None:
        if self._work is not None:  # a handler or a pause holds the reading: keep the order
            self._backlog += data
            return
        events = self._decode(self._take(data))
        if events is not None:
            self.handle(events)

    def handle(self, events: list[Any]) -> None:
        """Hand one read's events to ``on_event`` in order, then write what they queued (a subclass may
        take a read's events together). An awaitable from ``on_event`` holds the rest back."""
        try:
            for index, event in enumerate(events):
                if self.is_closing():
                    return
                pending = self.on_event(event)
                if pending is not None:
                    self._hold(pending, events[index + 1 :])
                    return
        except Exception as err:  # as in ``_finish``: the connection ends, the error named
            self._failed(err)
            return
        self.flush()
        if self._backlog or (self.paced and self._writable is not None and not self._writable.done()):
            self._hold(None, [])

    def receive(self, data: bytes) -> list[Any]:
        """The codec's events for ``data`` (a subclass may take a faster path)."""
        return cast(list[Any], self.codec.receive_data(data))

    def _take(self, data: bytes) -> bytes:
        """The bytes to decode this turn; the rest of the read waits in the backlog."""
        if self.chunk and len(data) > self.chunk:
            self._backlog = data[self.chunk :] + self._backlog
            return data[: self.chunk]
        return data

    def _decode(self, data: bytes) -> list[Any] | None:
        try:
            return self.receive(data)
        except ProtocolError as err:
            self.fail(err)
            return None

    def _hold(self, pending: Awaitable[Any] | None, events: list[Any]) -> None:
        """Stop reading until ``pending`` is done, then ``events``, then the backlog (in a task)."""
        if self.transport is not None:
            self.transport.pause_reading()
        self._work = asyncio.ensure_future(self._finish(pending, events))
        self._work.add_done_callback(lambda work: self._released(pending))

    async def _finish(self, pending: Awaitable[Any] | None, events: list[Any]) -> None:
        try:
            if pending is not None:
                await pending
            await self._deliver(events)
            while not self.closed.done():
                if self.paced:
                    await self.drain()
                if not self._backlog:
                    return
                await asyncio.sleep(0)  # one chunk per turn: the loop's other work goes first
                data, self._backlog = self._backlog, b""
                decoded = self._decode(self._take(data))
                if decoded is None:
                    return
                await self._deliver(decoded)
        except Exception as err:  # a handler failed: the connection ends, the error named
            self._failed(err)

    def _failed(self, err: Exception) -> None:
        """A handler raised ``err``: the connection ends with it; an error that is not a protocol or
        connection error is a handler's bug, which the loop's exception handler also reports."""
        self.fail(err)
        if not isinstance(err, (ProtocolError, ConnectionError)):
            asyncio.get_running_loop().call_exception_handler(
                {"message": f"{self.name}: an event handler failed", "exception": err, "protocol": self}
            )

    async def _deliver(self, events: list[Any]) -> None:
        for event in events:
            if self.is_closing():
                return
            pending = self.on_event(event)
            if pending is not None:
                await pending
            self.flush()

    def _released(self, pending: Awaitable[Any] | None) -> None:
        self._work = None
        if inspect.iscoroutine(pending):
            pending.close()  # never started if the connection ended first: not an error
        if self.transport is not None and not self.closed.done():
            self.transport.resume_reading()


async def connect(
    factory: Callable[[], _S],
    host: str,
    port: int,
    *,
    timeout: float,
    name: str,
    local_addr: tuple[str, int] | None = None,
) -> _S:
    """Open a connection to ``host``:``port`` for the shell ``factory`` makes (from ``local_addr`` if
    given: a fake robot dials from its own address); UrTimeoutError or ConnectionLostError
    (``<name>: cannot connect to …``) if it cannot."""
    loop = asyncio.get_running_loop()
    try:
        # asyncio.timeout, not wait_for: on 3.11 wait_for returns the connection when the caller's
        # cancellation lands as the connection completes, and the cancellation is lost (a supervisor
        # being stopped then carries on: `serve` hung at shutdown under load)
        async with asyncio.timeout(timeout):
            _, shell = await loop.create_connection(factory, host, port, local_addr=local_addr)
    except TimeoutError as err:
        raise UrTimeoutError(f"{name}: no connection to {host}:{port} within {timeout} s") from err
    except (OSError, UnicodeError) as err:  # UnicodeError: a host name IDNA cannot encode
        why = getattr(err, "strerror", None) or err
        raise ConnectionLostError(f"{name}: cannot connect to {host}:{port}: {why}") from err
    return shell


async def serve(factory: Callable[[], Shell], host: str, port: int) -> asyncio.Server:
    """Listen on ``host``:``port``; every connection gets a shell from ``factory``."""
    loop = asyncio.get_running_loop()
    return await loop.create_server(factory, host, port, reuse_address=True)
