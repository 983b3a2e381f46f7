"""Start-up of a UR robot and restarts of its control program: power on, release the brakes, then send
the program (headless) or play it (External Control URCap).

Without a dashboard (PolyScope X, or it refused the connection) power-on and brake release go over
the primary interface as controller commands, as urcl does; a URCap program can then only be started
on the pendant. One start-up or restart at a time: a second one while one is under way is refused.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncIterator
from typing import Any

from urdaemon.backends.ur.dashboard_link import DashboardLink
from urdaemon.backends.ur.links import UrLinks
from urdaemon.backends.ur.program import ControlProgram
from urdaemon.backends.ur.reverse_channel import ReverseChannel
from urdaemon.backends.ur.servers import CallbackServer
from urdaemon.cell.robot_options import Robot
from urdaemon.errors import BackendError, RobotFaultError, UrDaemonError, UrTimeoutError
from urdaemon.model import RobotMode, RobotState
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import primary as prim

__all__ = ["MODE_POLL_S", "STARTUP_TIMEOUT_S", "StartUp"]

log = logging.getLogger("urdaemon.ur")

STARTUP_TIMEOUT_S = 30.0
"""How long power-on and brake release may take (urcl polls for 30 s)."""
MODE_POLL_S = 0.05
"""How often start-up looks at the robot mode while it waits for a power step."""


class StartUp:
    """Start-up and program restarts of one UR robot (``robot``): through its ``links`` (dashboard,
    primary, the program sent headless), telling its ``program`` and ``channel`` (the reverse socket's
    state machine) a program is coming, reading its ``state`` once RTDE streams again
    (``first_package``) and whether the program holds its ``reverse_link``."""

    def __init__(
        self,
        robot: Robot,
        *,
        links: UrLinks,
        program: ControlProgram,
        channel: ReverseChannel,
        reverse_link: CallbackServer,
        state: RobotState,
        first_package: asyncio.Event,
    ) -> None:
        self.robot = robot
        self.links = links
        self.program = program
        self.channel = channel
        self.reverse_link = reverse_link
        self.state = state
        self.first_package = first_package
        self._lock = asyncio.Lock()
        """Held by startup and resend_program: a second call while one is under way is refused."""

    async def startup(self) -> None:
        """Power on, release the brakes, and start the control program (headless) or play it (URCap)."""
        self.links.check_commanding()
        async with self._exclusive("start-up"):
            try:
                await self._startup()
            except UrDaemonError as err:
                self.program.startup_problem = f"start-up failed: {err}"
                raise
            self.program.startup_problem = ""

    async def _startup(self) -> None:
        board: DashboardLink | None
        try:
            board = await self.links.dashboard_link()
        except UrDaemonError as err:
            board = None
            log.info(
                "[%s] start-up without the dashboard (%s): using the primary interface", self.robot.name, err
            )
        self.channel.take_back()
        deadline = time.monotonic() + STARTUP_TIMEOUT_S
        try:  # decide on fresh state, not on what the last connection left behind
            await asyncio.wait_for(self.first_package.wait(), STARTUP_TIMEOUT_S)
        except TimeoutError as err:
            raise UrTimeoutError("no RTDE data to start up from") from err
        state = self.state
        if state.robot_mode not in (RobotMode.IDLE, RobotMode.RUNNING):
            await self._power_step(board, dash.PowerOn(), prim.ControllerCommand.POWER_ON, "power on")
            await self._wait_mode((RobotMode.IDLE, RobotMode.RUNNING), deadline)
        if state.robot_mode is not RobotMode.RUNNING:
            await self._power_step(
                board, dash.BrakeRelease(), prim.ControllerCommand.BRAKE_RELEASE, "brake release"
            )
            await self._wait_mode((RobotMode.RUNNING,), deadline)
        if self.robot.headless:
            # the cycle may already have sent it the moment the brakes came off: a second program
            # would replace the first while it is still connecting back
            self.links.send_program(time.monotonic(), force=False)
        elif not self.reverse_link.connected:
            if board is None:
                raise BackendError(
                    "no dashboard to play the External Control program (PolyScope X, or the dashboard "
                    "refused the connection): press play on the pendant, or run headless"
                )
            self.program.expect(time.monotonic())
            reply = await board.command(dash.Play())
            if not reply.success:
                raise RobotFaultError(f"play refused: {reply.text}")

    async def _power_step(
        self, board: DashboardLink | None, command: Any, fallback: prim.ControllerCommand, what: str
    ) -> None:
        """One power-on step: on the dashboard, or as a controller command on the primary interface."""
        if board is not None:
            reply = await board.command(command)
            if not reply.success:
                raise RobotFaultError(f"{what} refused: {reply.text}")
            return
        self.links.send_script(str(fallback))

    async def _wait_mode(self, modes: tuple[RobotMode, ...], deadline: float) -> None:
        state = self.state
        while state.robot_mode not in modes:
            if time.monotonic() > deadline:
                raise UrTimeoutError(f"robot mode {state.robot_mode.name} did not become {modes[0].name}")
            await asyncio.sleep(MODE_POLL_S)

    async def resend_program(self) -> None:
        """Send the control program again (headless) or play the loaded one (URCap).

        Refused while a start-up or restart is under way, and while the program sent last is still
        connecting back (a second program would only replace it)."""
        links, program = self.links, self.program
        links.check_commanding()
        async with self._exclusive("program restart"):
            if self.robot.headless:
                if links.primary is None:
                    raise BackendError("not connected to the robot")
                pending = program.still_connecting(time.monotonic())
                if pending is not None:
                    raise BackendError(pending)
                self.channel.take_back()
                links.send_program(time.monotonic(), force=True)
            else:
                self.channel.take_back()
                program.expect(time.monotonic())
                reply = await (await links.dashboard_link()).command(dash.Play())
                if not reply.success:
                    raise BackendError(f"play refused: {reply.text}")

    @contextlib.asynccontextmanager
    async def _exclusive(self, what: str) -> AsyncIterator[None]:
        """Run a start-up or program restart alone: refuse (BackendError) while one is under way."""
        if self._lock.locked():
            raise BackendError(f"a start-up or program restart is already under way: {what} refused")
        async with self._lock:
            yield
