"""The servers the robot's control program dials: reverse, script sender, trajectory, script command.

Each listens on one of the robot's configured host ports, accepts only the robot's own address and
keeps one connection (a newer one from the robot replaces an older one: a new program replaced the
old), and wraps the daemon
side of its sans-IO codec. ``send`` writes at once (one write per frame: the script reads fixed-size
frames); events and connect/disconnect reach the owner through callbacks on the loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import logging
import socket
from collections.abc import Callable
from typing import Any, Protocol, cast

from urdaemon.errors import ProtocolError
from urdaemon.protocols import reverse, script_command, script_sender, trajectory_point
from urdaemon.protocols._buffer import Side

__all__ = ["CallbackLink", "CallbackServer", "CallbackServers", "ServerHooks"]

log = logging.getLogger("urdaemon.ur")


class _Codec(Protocol):
    def receive_data(self, data: bytes) -> list[Any]: ...
    def send(self, message: Any) -> None: ...
    def data_to_send(self) -> bytes: ...


class ServerHooks(Protocol):
    """What a server tells its owner (all called on the loop)."""

    def on_link(self, name: str, connected: bool, reason: str) -> None: ...
    def on_event(self, name: str, event: Any) -> None: ...


class CallbackLink(asyncio.Protocol):
    """One accepted connection from the robot."""

    def __init__(self, server: CallbackServer) -> None:
        self.server = server
        self.codec: _Codec = server.make_codec()
        self.transport: asyncio.Transport | None = None
        self.peer = ""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # uvloop's transports are not asyncio.Transport subclasses but offer the same methods
        self.transport = cast(asyncio.Transport, transport)
        peer = transport.get_extra_info("peername")
        self.peer = str(peer[0]) if peer else ""
        if not self.server.admit(self):
            transport.close()
            return
        sock = transport.get_extra_info("socket")
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)

    def data_received(self, data: bytes) -> None:
        try:
            events = self.codec.receive_data(data)
        except ProtocolError as err:
            self.server.lost(self, f"{self.server.name}: {err}")
            self.close()
            return
        for event in events:
            self.server.hooks.on_event(self.server.name, event)

    def connection_lost(self, exc: Exception | None) -> None:
        self.server.lost(
            self, f"{self.server.name}: connection {'lost: ' + str(exc) if exc else 'closed by the robot'}"
        )

    def send(self, message: Any) -> None:
        """Encode and write ``message`` now; LocalProtocolError if it cannot be encoded."""
        self.codec.send(message)
        self.write(self.codec.data_to_send())

    def write(self, data: bytes) -> None:
        """Write bytes already encoded for this protocol (the 500 Hz servoj frame)."""
        if self.transport is not None and not self.transport.is_closing():
            self.transport.write(data)

    def close(self) -> None:
        """Close this connection."""
        if self.transport is not None:
            self.transport.close()


class CallbackServer:
    """A listening port for one kind of connection from the robot."""

    def __init__(
        self, name: str, port: int, robot_address: str, make_codec: Callable[[], _Codec], hooks: ServerHooks
    ) -> None:
        self.name = name
        self.port = port
        self.robot_address = robot_address
        self.make_codec = make_codec
        self.hooks = hooks
        self.link: CallbackLink | None = None
        self.refused = 0
        self._server: asyncio.Server | None = None

    async def start(self, host: str) -> None:
        """Listen on ``host``:port."""
        loop = asyncio.get_running_loop()
        self._server = await loop.create_server(
            lambda: CallbackLink(self), host, self.port, reuse_address=True
        )

    def admit(self, link: CallbackLink) -> bool:
        """Accept the robot's own address, one connection at a time."""
        if not _same_host(link.peer, self.robot_address):
            self.refused += 1
            log.warning(
                "%s: refused a connection from %s (the robot is %s)", self.name, link.peer, self.robot_address
            )
            return False
        old = self.link
        if old is not None:
            # the robot runs one program at a time: a new connection means a new program replaced the
            # old one, whose connection is dead even if its close has not reached us yet
            log.info("%s: a new connection from %s replaces the previous one", self.name, link.peer)
            self.link = None
            old.close()
            self.hooks.on_link(self.name, False, f"{self.name}: replaced by a new connection")
        self.link = link
        self.hooks.on_link(self.name, True, f"{self.name}: connected from {link.peer}")
        return True

    def lost(self, link: CallbackLink, reason: str) -> None:
        """Forget ``link`` if it is the current one and tell the owner."""
        if self.link is link:
            self.link = None
            self.hooks.on_link(self.name, False, reason)

    @property
    def connected(self) -> bool:
        """True while the robot is connected."""
        return self.link is not None

    def send(self, message: Any) -> bool:
        """Send to the connected robot; False if none is connected."""
        link = self.link
        if link is None:
            return False
        link.send(message)  # LocalProtocolError propagates: the caller built a message that cannot be sent
        return True

    def write(self, data: bytes) -> bool:
        """Write an already encoded frame to the connected robot; False if none is connected."""
        link = self.link
        if link is None:
            return False
        link.write(data)
        return True

    async def close(self) -> None:
        """Close the connection and stop listening."""
        if self.link is not None:
            self.link.close()
        if self._server is not None:
            self._server.close()
            with contextlib.suppress(Exception):
                await self._server.wait_closed()


class CallbackServers:
    """The four servers of one robot."""

    def __init__(self, robot_address: str, ports: dict[str, int], hooks: ServerHooks) -> None:
        self.reverse = CallbackServer(
            "reverse", ports["reverse"], robot_address, lambda: reverse.ReverseConnection(Side.DAEMON), hooks
        )
        self.script_sender = CallbackServer(
            "script_sender",
            ports["script_sender"],
            robot_address,
            lambda: script_sender.ScriptSenderConnection(Side.DAEMON),
            hooks,
        )
        self.trajectory = CallbackServer(
            "trajectory",
            ports["trajectory"],
            robot_address,
            lambda: trajectory_point.TrajectoryPointConnection(Side.DAEMON),
            hooks,
        )
        self.script_command = CallbackServer(
            "script_command",
            ports["script_command"],
            robot_address,
            lambda: script_command.ScriptCommandConnection(Side.DAEMON),
            hooks,
        )
        self.all = (self.reverse, self.script_sender, self.trajectory, self.script_command)

    def set_robot_address(self, address: str) -> None:
        """Accept connections from ``address`` (the robot's resolved IP)."""
        for server in self.all:
            server.robot_address = address

    async def start(self, host: str) -> None:
        """Listen on every port (closing what started if one fails)."""
        try:
            for server in self.all:
                await server.start(host)
        except OSError:
            await self.close()
            raise

    async def close(self) -> None:
        """Close every server."""
        for server in self.all:
            await server.close()


def _same_host(peer: str, robot: str) -> bool:
    """True if ``peer`` is the robot (IPv4-mapped IPv6 and names that resolve alike compare equal)."""
    try:
        a, b = ipaddress.ip_address(peer), ipaddress.ip_address(robot)
    except ValueError:
        return peer == robot
    if isinstance(a, ipaddress.IPv6Address) and a.ipv4_mapped is not None:
        a = a.ipv4_mapped
    return a == b
