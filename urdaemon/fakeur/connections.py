"""The connections of one fake controller: each client's shell admitted and counted, and every write
through one place that applies the injected faults and protects the controller from clients that do
not read.

``shell`` makes the shell (``urdaemon.shell``) of one service's connection: a refused service
closes the connection at once, and a client that breaks its protocol is dropped as a real controller
drops it. ``write`` (the shells' ``transmit``) skips whole messages to a client whose unsent backlog
passes ``MAX_BACKLOG_BYTES`` (it stays connected: ur_rtde sends scripts on 30003 and never reads it),
and delays or splits them as the faults ask. A request/response service is ``paced``: its shell stops
reading a client that does not read the replies (TCP flow control), so such a client is simply not
read meanwhile; every service reads at most ``READ_CHUNK`` bytes per loop turn.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable
from typing import Any

from urdaemon.errors import ConnectionLostError
from urdaemon.fakeur.faults import FaultInjector
from urdaemon.shell import Shell

__all__ = ["MAX_BACKLOG_BYTES", "READ_CHUNK", "Connections", "ServiceShell"]

log = logging.getLogger("urdaemon.fakeur")

READ_CHUNK = 4096
"""Bytes read from a client at a time: a few hundred requests at most are handled in one turn."""
MAX_BACKLOG_BYTES = 1 << 20
"""A client that leaves more than this unsent (it does not read) misses messages until it catches up."""


class ServiceShell(Shell):
    """One client's connection to a service of the fake: admitted by ``Connections``, its writes
    through ``Connections.write``; ``on_open`` runs once it is admitted."""

    def __init__(
        self,
        connections: Connections,
        service: str,
        codec: Any,
        on_event: Callable[[Any], Awaitable[Any] | None],
        *,
        on_open: Callable[[ServiceShell], None] | None = None,
        on_end: Callable[[ServiceShell], None] | None = None,
        paced: bool = False,
    ) -> None:
        super().__init__(
            codec, service, on_event, on_close=self._ended, peer_name="client", chunk=READ_CHUNK, paced=paced
        )
        self.connections = connections
        self.service = service
        self.on_open = on_open
        self.on_end = on_end
        self._admitted = False

    def opened(self) -> bool:
        self._admitted = self.connections.admit(self)
        if self._admitted and self.on_open is not None:
            self.on_open(self)
        return self._admitted

    def transmit(self, data: bytes) -> None:
        self.connections.write(self.service, self, data)

    def _ended(self, reason: Exception) -> None:
        if not self._admitted:
            return
        self.connections.forget(self, reason)
        if self.on_end is not None:
            self.on_end(self)


class Connections:
    """Every open client connection of one controller, by service."""

    def __init__(self, address: str, faults: FaultInjector) -> None:
        self.address = address
        self.faults = faults
        self.writers: dict[str, set[Shell]] = {}
        """The open connections of each service (their shells)."""
        self.tasks: set[asyncio.Task[Any]] = set()
        """Delayed or split writes still under way (and other helper tasks), cancelled on close."""

    def shell(
        self,
        service: str,
        codec: Any,
        on_event: Callable[[ServiceShell, Any], Awaitable[Any] | None],
        **options: Any,
    ) -> ServiceShell:
        """The shell of one new ``service`` connection; ``on_event(shell, event)`` gets its events."""
        shell: ServiceShell = ServiceShell(
            self, service, codec, lambda event: on_event(shell, event), **options
        )
        return shell

    def admit(self, shell: ServiceShell) -> bool:
        """Count a new connection in, unless the faults refuse its service (then it is closed)."""
        if self.faults.is_refused(shell.service):
            return False
        self.writers.setdefault(shell.service, set()).add(shell)
        return True

    def forget(self, shell: ServiceShell, reason: Exception) -> None:
        """A connection ended: a client that broke the protocol is dropped, as a real controller drops it."""
        self.writers[shell.service].discard(shell)
        if not isinstance(reason, ConnectionLostError):
            log.info("%s %s: dropping client: %s", self.address, shell.service, reason)
            shell.close()

    def write(self, service: str, writer: Shell, data: bytes) -> None:
        """Send ``data`` to one client of ``service`` (never waits)."""
        if not data or writer.is_closing():
            return
        transport = writer.transport
        if transport is not None and transport.get_write_buffer_size() > MAX_BACKLOG_BYTES:
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
