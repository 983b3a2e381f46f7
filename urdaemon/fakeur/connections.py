"""The connections of one fake controller: each client's handler guarded, and every write through one
place that applies the injected faults and protects the controller from clients that do not read.

``guard`` wraps a service's handler: a refused service closes the connection at once, TCP_NODELAY is
set, and a client that breaks its protocol is dropped as a real controller drops it. ``write`` skips
whole messages to a client whose unsent backlog passes ``MAX_BACKLOG_BYTES`` (it stays connected:
ur_rtde sends scripts on 30003 and never reads it), and delays or splits them as the faults ask.
``paced`` is what a request/response service does after each read: it waits while its client does
not read the replies (TCP flow control), so such a client is simply not read meanwhile.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from collections.abc import Callable
from typing import Any

from urdaemon.errors import ProtocolError
from urdaemon.fakeur.faults import FaultInjector

__all__ = ["MAX_BACKLOG_BYTES", "READ_CHUNK", "Connections", "paced"]

log = logging.getLogger("urdaemon.fakeur")

READ_CHUNK = 4096
"""Bytes read from a client at a time: a few hundred requests at most are handled in one turn."""
MAX_BACKLOG_BYTES = 1 << 20
"""A client that leaves more than this unsent (it does not read) misses messages until it catches up."""

Handler = Callable[[asyncio.StreamReader, asyncio.StreamWriter], Any]


class Connections:
    """Every open client connection of one controller, by service."""

    def __init__(self, address: str, faults: FaultInjector) -> None:
        self.address = address
        self.faults = faults
        self.writers: dict[str, set[asyncio.StreamWriter]] = {}
        self.tasks: set[asyncio.Task[Any]] = set()
        """Delayed or split writes still under way (and other helper tasks), cancelled on close."""

    def guard(self, service: str, handler: Handler) -> Handler:
        """``handler`` for one ``service`` connection, with the faults and the bookkeeping."""

        async def serve(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            if self.faults.is_refused(service):
                writer.close()
                return
            sock = writer.get_extra_info("socket")
            if sock is not None:
                with contextlib.suppress(OSError):
                    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self.writers.setdefault(service, set()).add(writer)
            try:
                await handler(reader, writer)
            except (ConnectionError, asyncio.IncompleteReadError):
                pass
            except ProtocolError as err:  # a client that breaks the protocol is dropped, as a real one is
                log.info("%s %s: dropping client: %s", self.address, service, err)
            finally:
                self.writers[service].discard(writer)
                writer.close()

        return serve

    def write(self, service: str, writer: asyncio.StreamWriter, data: bytes) -> None:
        """Send ``data`` to one client of ``service`` (never waits)."""
        if not data or writer.is_closing():
            return
        if writer.transport.get_write_buffer_size() > MAX_BACKLOG_BYTES:
            return  # whole messages are skipped, so what it reads later is still well framed
        mangled = self.faults.mangle(service, data)
        if mangled.delay_s <= 0.0 and len(mangled.pieces) == 1:
            writer.write(mangled.pieces[0])
            return

        async def later() -> None:
            if mangled.delay_s > 0:
                await asyncio.sleep(mangled.delay_s)
            for piece in mangled.pieces:
                if writer.is_closing():
                    return
                writer.write(piece)
                await writer.drain()

        self.spawn(later())

    def spawn(self, coroutine: Any) -> None:
        """Run ``coroutine`` as a task of this controller (cancelled when it closes)."""
        task = asyncio.get_running_loop().create_task(coroutine)
        self.tasks.add(task)
        task.add_done_callback(self.tasks.discard)

    def drop(self, service: str) -> int:
        """Close every open connection of ``service`` (or ``*``); how many were closed."""
        closed = 0
        for name, writers in self.writers.items():
            if service in (name, "*"):
                for writer in list(writers):
                    writer.close()
                    closed += 1
        return closed


async def paced(writer: asyncio.StreamWriter, data: bytes) -> None:
    """After handling one read: wait while the client does not read its replies (TCP flow control:
    it is not read meanwhile), and give others a turn when more is waiting (a full read)."""
    await writer.drain()
    if len(data) >= READ_CHUNK:
        await asyncio.sleep(0)
