"""The daemon's links to one UR controller: RTDE (the state stream and its input package), the primary
interface (scripts and the robot's messages) and the dashboard (one command at a time, connected when
first needed and again after it dropped); sending the control program headless; refusing to command a
read-only robot.

``UrLinks`` is the one owner of these connections: the backend connects, watches and closes them; its
helpers (``robot_commands``, ``startup``, ``diagnosis``) are given the ``UrLinks`` and send through it.
Nothing here reads the clock or runs the cycle.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Any

from urdaemon.backends.ur.dashboard_link import DashboardLink
from urdaemon.backends.ur.primary_link import PrimaryLink
from urdaemon.backends.ur.program import ControlProgram
from urdaemon.backends.ur.rtde_link import RtdeLink, input_recipe, output_recipe
from urdaemon.cell.robot_options import READ_ONLY_REASON
from urdaemon.errors import BackendError, ConnectionLostError, UrTimeoutError
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols.rtde_variables import DOUBLE, INPUT_VARIABLES

__all__ = ["CONTROLLER_WAIT_S", "UrLinks"]

log = logging.getLogger("urdaemon.ur")

CONTROLLER_WAIT_S = 0.5
"""Until the controller was first reached, how often a refused RTDE connection is tried again: a
daemon started before its controller (or the fakes) waits for it instead of failing."""

_DOUBLE_INPUTS = frozenset(name for name, kind in INPUT_VARIABLES.items() if kind == DOUBLE)
"""The RTDE inputs sent as doubles (the rest of an input package are integers)."""


class UrLinks:
    """The RTDE, primary and dashboard links to the controller at ``address`` (see the module's
    docstring). ``rtde`` and ``primary`` are None while not connected; only this object sets them."""

    def __init__(self, address: str, *, read_only: bool, program: ControlProgram) -> None:
        self.address = address
        self.read_only = read_only
        """A read-only robot is watched, not commanded: no RTDE inputs, ``check_commanding`` refuses."""
        self.program = program
        """The control program ``send_program`` sends on the primary interface."""
        self.rtde: RtdeLink | None = None
        self.primary: PrimaryLink | None = None
        self._dashboard: DashboardLink | None = None
        self._dashboard_lock = asyncio.Lock()
        """Held while the dashboard connects: one connection however many callers want it."""
        self._inputs = input_recipe()
        self._reached = False
        """Whether RTDE ever connected: until then a refused connection is waited out, not a failure."""

    def check_commanding(self) -> None:
        """Refuse a read-only robot."""
        if self.read_only:
            raise BackendError(READ_ONLY_REASON)

    # ---- connect and close ---------------------------------------------------------------------------

    async def connect_rtde(self, on_package: Callable[[tuple[Any, ...]], None]) -> RtdeLink:
        """Connect RTDE and handshake (the driver's recipes; no inputs on a read-only robot); not
        streaming yet (``RtdeLink.start``). Until the controller was first reached, a refused
        connection (it does not listen yet: the daemon started first) is said once, at INFO, and
        tried again: not a failure."""
        told = False
        while True:
            try:
                rtde = self.rtde = await RtdeLink.connect(self.address, on_package)
                break
            except ConnectionLostError as err:
                if self._reached or not isinstance(err.__cause__, ConnectionRefusedError):
                    raise
                if not told:
                    told = True
                    name = self.program.robot.name
                    log.info("[%s] waiting for the controller at %s (%s)", name, self.address, err)
                await asyncio.sleep(CONTROLLER_WAIT_S)
        self._reached = True
        await rtde.handshake(output_recipe(), None if self.read_only else self._inputs)
        return rtde

    async def connect_primary(self, on_message: Callable[[Any], None]) -> PrimaryLink:
        """Connect the primary interface; it reads from now on (``PrimaryLink.run``)."""
        primary = self.primary = await PrimaryLink.connect(self.address, on_message)
        return primary

    async def dashboard_link(self) -> DashboardLink:
        """The dashboard connection, opened now if there is none (it does not need the other links)."""
        async with self._dashboard_lock:
            if self._dashboard is None:
                self._dashboard = await DashboardLink.connect(self.address)
            return self._dashboard

    def drop_dashboard(self) -> None:
        """Close the dashboard connection; the next command connects again."""
        if self._dashboard is not None:
            self._dashboard.close()
            self._dashboard = None

    def close(self) -> None:
        """Close every link (a link dropped, or the daemon stops)."""
        for link in (self.rtde, self.primary, self._dashboard):
            if link is not None:
                link.close()
        self.rtde = self.primary = self._dashboard = None

    # ---- send ---------------------------------------------------------------------------------------

    def send_inputs(self, fields: dict[str, Any]) -> None:
        """One RTDE input package: ``fields`` set, every other input of the recipe 0."""
        rtde = self.rtde
        if rtde is None:
            raise BackendError("not connected to the robot")
        values = []
        for name in self._inputs:
            value = fields.get(name, 0)
            values.append(float(value) if name in _DOUBLE_INPUTS else int(value))
        rtde.send_inputs(values)

    def send_script(self, text: str) -> None:
        """Send URScript text on the primary interface (BackendError without one)."""
        primary = self.primary
        if primary is None:
            raise BackendError("not connected to the robot")
        primary.send_script(text)

    def send_program(self, now: float, *, force: bool) -> None:
        """Send the control program headless if it is due (``ControlProgram.send_headless``)."""
        self.program.send_headless(self.primary, now, force=force)

    async def dashboard_command(self, command: Any) -> Any:
        """Send a dashboard command and return its typed reply: a connection that dropped is opened once
        more; after a timeout it is dropped (its late reply would answer the next command)."""
        try:
            return await (await self.dashboard_link()).command(command)
        except ConnectionLostError:
            self.drop_dashboard()  # the dashboard dropped: connect once more
            return await (await self.dashboard_link()).command(command)
        except UrTimeoutError:
            self.drop_dashboard()  # its late reply would be read as the next command's answer
            raise

    async def dashboard_query(self, line: str, timeout: float) -> str:
        """Send a dashboard line and return the reply's text within ``timeout`` s (``UrTimeoutError``
        after it; the link is dropped then, as its late reply would answer the next command)."""
        command = dash.parse_command(line) or dash.Raw(line)
        timeout = max(timeout, 0.001)
        try:  # a connection that does not come is given up within the time too (nothing sent yet)
            link = await asyncio.wait_for(self.dashboard_link(), timeout)
        except TimeoutError:
            raise UrTimeoutError(f"dashboard: not connected within {timeout:.1f} s") from None
        try:
            reply = await link.command(command, timeout=timeout)
        except (ConnectionLostError, UrTimeoutError):
            self.drop_dashboard()
            raise
        return str(getattr(reply, "text", ""))
