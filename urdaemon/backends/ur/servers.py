"""The servers the robot's control program dials: reverse, script sender, trajectory, script command.

Each listens on one of the robot's configured host ports, accepts only the robot's own address,
keeps one connection, and wraps the daemon side of its sans-IO codec in the shell
(``urdaemon.shell``). ``send`` writes at once (one write per frame: the script reads fixed-size
frames); events and connect/disconnect reach the owner through callbacks on the loop.

Who may connect (the callback-link rules, docs/ursim.md):

* Only the robot's address; anything else is closed at once and counted (logged the first time and
  then every ``REFUSAL_LOG_EVERY``-th time, with the count).
* One connection per port, as urcl's reverse interface allows one client. While the program's link
  is up, a second connection is refused, even from the robot's address: it must not take over a
  live link (it would get the program's frames, and its own bytes would be read as the program's).
* A replacement is accepted only after the daemon started a new program (``expect_program``: it
  sent one headless, played one, or handed one to a URCap whose previous program had ended): a new
  program connects while the old one's close may still be on its way. That permission lasts
  ``PROGRAM_CONNECT_WINDOW_S`` or until the new program holds all its links
  (``CallbackServers.program_connected``), whichever comes first; within it the newest connection
  from the robot wins, so a stray that got in first is replaced by the program's own.
* The script-sender port is a request/response with no stream to steal: there a newer connection
  from the robot replaces an older one (a URCap that gave up must not lock the port).
* Only the current link's messages reach the owner: bytes from a link that was replaced or refused
  are dropped.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import ipaddress
import logging
import time
from collections.abc import Callable
from typing import Any, Protocol

from urdaemon.backends.ur.route import ListenPlan, listen_plan
from urdaemon.cell.robot_options import UrOptions
from urdaemon.errors import BackendError, ConnectionLostError
from urdaemon.protocols import reverse, script_command, script_sender, trajectory_point
from urdaemon.protocols._buffer import Side
from urdaemon.shell import Codec, Shell, serve

__all__ = [
    "PROGRAM_CONNECT_WINDOW_S",
    "REFUSAL_LOG_EVERY",
    "REPLACED",
    "CallbackLink",
    "CallbackServer",
    "CallbackServers",
    "ServerHooks",
]

log = logging.getLogger("urdaemon.ur")

PROGRAM_CONNECT_WINDOW_S = 15.0
"""After the daemon starts a program, how long its connections may replace the old program's links
(the script dials each port up to 5 times 0.2 s apart; a URCap first fetches the script)."""
REPLACED = "replaced by the new program's connection"
"""The end of the reason ``on_link`` gets when a new program's connection replaced the old one."""
REFUSAL_LOG_EVERY = 100
"""Refused connections are logged the first time and then every this many times (with the count)."""


class ServerHooks(Protocol):
    """What a server tells its owner (all called on the loop)."""

    def on_link(self, name: str, connected: bool, reason: str) -> None: ...
    def on_event(self, name: str, event: Any) -> None: ...


class CallbackLink(Shell):
    """One accepted connection from the robot (the shell around the server's codec)."""

    def __init__(self, server: CallbackServer) -> None:
        codec = server.make_codec()
        super().__init__(codec, server.name, self._on_event, on_close=self._lost, keepalive=True)
        self.server = server
        self.peer = ""

    def opened(self) -> bool:
        assert self.transport is not None
        peer = self.transport.get_extra_info("peername")
        self.peer = str(peer[0]) if peer else ""
        return self.server.admit(self)

    def data_received(self, data: bytes) -> None:
        if self.server.link is not self:  # replaced or refused: its bytes are nobody's messages
            return
        super().data_received(data)

    def _on_event(self, event: Any) -> None:
        self.server.hooks.on_event(self.server.name, event)

    def _lost(self, reason: Exception) -> None:
        text = str(reason) if isinstance(reason, ConnectionLostError) else f"{self.server.name}: {reason}"
        self.server.lost(self, text)


class CallbackServer:
    """A listening port for one kind of connection from the robot."""

    def __init__(
        self, name: str, port: int, robot_address: str, make_codec: Callable[[], Codec], hooks: ServerHooks
    ) -> None:
        self.name = name
        self.port = port
        self.robot_address = robot_address
        self.make_codec = make_codec
        self.hooks = hooks
        self.link: CallbackLink | None = None
        self.refused = 0
        self.replaceable = False
        """A newer connection from the robot replaces the live one at any time (the script sender)."""
        self._replace_until = 0.0
        self.connected_at = -1e9
        """When the current (or last) link was accepted (``time.monotonic()``)."""
        self._server: asyncio.Server | None = None

    async def start(self, host: str) -> None:
        """Listen on ``host``:port; BackendError (one line, naming the port) if it cannot."""
        try:
            self._server = await serve(lambda: CallbackLink(self), host, self.port)
        except OSError as err:
            if err.errno == errno.EADDRINUSE:
                why = (
                    "is in use: another program listens there (another urdaemon, a ROS driver, or "
                    "another robot's callback port); free it or set this robot's ports: in the cell file"
                )
            elif err.errno == errno.EADDRNOTAVAIL:
                why = "cannot be opened: this machine has no such address (check ur.listen_address)"
            else:
                why = f"cannot be opened: {err.strerror or err}"
            raise BackendError(f"the {self.name} callback port {host}:{self.port} {why}") from None

    def expect_program(self, window: float = PROGRAM_CONNECT_WINDOW_S) -> None:
        """A new program was started: its connection may replace the live one for ``window`` s."""
        self._replace_until = time.monotonic() + window

    def end_replacements(self) -> None:
        """The new program's connection is in: from now on a second connection is a stray."""
        self._replace_until = 0.0

    def admit(self, link: CallbackLink) -> bool:
        """Accept the robot's own address, one connection at a time (see the module's rules)."""
        if not _same_host(link.peer, self.robot_address):
            self._refuse(link, f"it is not the robot ({self.robot_address})")
            return False
        old = self.link
        if old is not None:
            if not self.replaceable and time.monotonic() > self._replace_until:
                self._refuse(link, "the control program's link is live and no new program was started")
                return False
            # a new program replaced the old one, whose connection is dead even if its close has not
            # reached us yet
            log.info("%s: a new connection from %s replaces the previous one", self.name, link.peer)
            self.link = None
            old.close()
            self.hooks.on_link(self.name, False, f"{self.name}: {REPLACED}")
        self.link = link
        self.connected_at = time.monotonic()
        self.hooks.on_link(self.name, True, f"{self.name}: connected from {link.peer}")
        return True

    def _refuse(self, link: CallbackLink, why: str) -> None:
        self.refused += 1
        if self.refused == 1 or self.refused % REFUSAL_LOG_EVERY == 0:
            log.warning(
                "%s: refused a connection from %s: %s (%d refused so far; logged every %dth)",
                self.name,
                link.peer,
                why,
                self.refused,
                REFUSAL_LOG_EVERY,
            )

    def lost(self, link: CallbackLink, reason: str) -> None:
        """Forget ``link`` if it is the current one and tell the owner."""
        if self.link is link:
            self.link = None
            self.hooks.on_link(self.name, False, reason)

    @property
    def connected(self) -> bool:
        """True while the robot is connected."""
        return self.link is not None

    def facts(self) -> dict[str, Any]:
        """Its port, whether it listens, and who is connected (the doctor's)."""
        link = self.link
        return {
            "port": self.port,
            "listening": self._server is not None,
            "connected": link is not None,
            "peer": link.peer if link is not None else None,
        }

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
            server, self._server = self._server, None
            with contextlib.suppress(Exception):
                await server.wait_closed()


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
        self.script_sender.replaceable = True
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
        self.program_links = (self.reverse, self.trajectory, self.script_command)
        """The links the control program holds while it runs (it dials them in the order
        trajectory, script command, reverse)."""
        self.listening_on: str | None = None
        """The address the servers listen on (None: they do not)."""

    def expect_program(self) -> None:
        """The daemon started a new program: its connections may replace the old program's."""
        for server in self.program_links:
            server.expect_program()

    def program_connected(self) -> None:
        """The program started last holds every link: no connection may replace them any more."""
        for server in self.program_links:
            server.end_replacements()

    def missing(self) -> list[str]:
        """The program's links that are not connected (empty while the program holds them all)."""
        return [server.name for server in self.program_links if server.link is None]

    def facts(self, dials: str) -> dict[str, Any]:
        """Where the servers listen, the address the program dials (``dials``), and each port's facts."""
        return {
            "listening_on": self.listening_on,
            "dials": dials,
            "ports": {server.name: server.facts() for server in self.all},
        }

    def set_robot_address(self, address: str) -> None:
        """Accept connections from ``address`` (the robot's resolved IP)."""
        for server in self.all:
            server.robot_address = address

    async def start(self, host: str) -> None:
        """Listen on every port (closing what started if one fails)."""
        try:
            for server in self.all:
                await server.start(host)
        except BackendError:
            await self.close()
            raise
        self.listening_on = host

    async def place(self, robot: str, options: UrOptions, name: str) -> ListenPlan:
        """Listen where the robot at ``robot`` reaches them (``route.listen_plan``, in a thread: it may
        resolve a name) and accept only its IP; ``name`` is the robot's, for the log."""
        plan = await asyncio.to_thread(listen_plan, robot, options)
        self.set_robot_address(plan.robot_ip)
        if await self.listen(plan.address):
            log.info("[%s] callback servers listening on %s, %s", name, plan.address, plan.why)
        return plan

    async def listen(self, host: str) -> bool:
        """Listen on ``host`` (see ``start``); if they listen on another address (the robot is now
        reached through another interface), close there first. True if they started now."""
        if host == self.listening_on:
            return False
        if self.listening_on is not None:
            log.info("callback servers: leaving %s for %s", self.listening_on, host)
            await self.close()
        await self.start(host)
        return True

    async def close(self) -> None:
        """Close every server (and their links); nothing if they do not listen."""
        self.listening_on = None
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
