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
from typing import TYPE_CHECKING, Any

from urdaemon.backends.ur.dashboard_link import DashboardLink
from urdaemon.errors import BackendError, RobotFaultError, UrDaemonError, UrTimeoutError
from urdaemon.model import RobotMode
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import primary as prim

if TYPE_CHECKING:
    from urdaemon.backends.ur.backend import UrBackend

__all__ = ["MODE_POLL_S", "STARTUP_TIMEOUT_S", "StartUp"]

log = logging.getLogger("urdaemon.ur")

STARTUP_TIMEOUT_S = 30.0
"""How long power-on and brake release may take (urcl polls for 30 s)."""
MODE_POLL_S = 0.05
"""How often start-up looks at the robot mode while it waits for a power step."""


class StartUp:
    """Start-up and program restarts of one UR backend (``ur``: the backend whose links they use)."""

    def __init__(self, ur: UrBackend) -> None:
        self.ur = ur
        self._lock = asyncio.Lock()
        """Held by startup and resend_program: a second call while one is under way is refused."""

    async def startup(self) -> None:
        """Power on, release the brakes, and start the control program (headless) or play it (URCap)."""
        ur = self.ur
        ur._services.check_commanding()
        async with self._exclusive("start-up"):
            try:
                await self._startup()
            except UrDaemonError as err:
                ur._program.startup_problem = f"start-up failed: {err}"
                raise
            ur._program.startup_problem = ""

    async def _startup(self) -> None:
        ur = self.ur
        board: DashboardLink | None
        try:
            board = await ur._dashboard_link()
        except UrDaemonError as err:
            board = None
            log.info("[%s] start-up without the dashboard (%s): using the primary interface", ur.name, err)
        ur._channel.take_back()
        deadline = time.monotonic() + STARTUP_TIMEOUT_S
        try:  # decide on fresh state, not on what the last connection left behind
            await asyncio.wait_for(ur._first_package.wait(), STARTUP_TIMEOUT_S)
        except TimeoutError as err:
            raise UrTimeoutError("no RTDE data to start up from") from err
        if ur.state.robot_mode not in (RobotMode.IDLE, RobotMode.RUNNING):
            await self._power_step(board, dash.PowerOn(), prim.ControllerCommand.POWER_ON, "power on")
            await self._wait_mode((RobotMode.IDLE, RobotMode.RUNNING), deadline)
        if ur.state.robot_mode is not RobotMode.RUNNING:
            await self._power_step(
                board, dash.BrakeRelease(), prim.ControllerCommand.BRAKE_RELEASE, "brake release"
            )
            await self._wait_mode((RobotMode.RUNNING,), deadline)
        if ur.robot.headless:
            # the cycle may already have sent it the moment the brakes came off: a second program
            # would replace the first while it is still connecting back
            ur._send_program(time.monotonic(), force=False)
        elif not ur.servers.reverse.connected:
            if board is None:
                raise BackendError(
                    "no dashboard to play the External Control program (PolyScope X, or the dashboard "
                    "refused the connection): press play on the pendant, or run headless"
                )
            ur._program.expect(time.monotonic())
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
        primary = self.ur._primary
        if primary is None:
            raise BackendError("not connected to the robot")
        primary.send_script(str(fallback))

    async def _wait_mode(self, modes: tuple[RobotMode, ...], deadline: float) -> None:
        state = self.ur.state
        while state.robot_mode not in modes:
            if time.monotonic() > deadline:
                raise UrTimeoutError(f"robot mode {state.robot_mode.name} did not become {modes[0].name}")
            await asyncio.sleep(MODE_POLL_S)

    async def resend_program(self) -> None:
        """Send the control program again (headless) or play the loaded one (URCap).

        Refused while a start-up or restart is under way, and while the program sent last is still
        connecting back (a second program would only replace it)."""
        ur = self.ur
        ur._services.check_commanding()
        async with self._exclusive("program restart"):
            if ur.robot.headless:
                if ur._primary is None:
                    raise BackendError("not connected to the robot")
                pending = ur._program.still_connecting(time.monotonic())
                if pending is not None:
                    raise BackendError(pending)
                ur._channel.take_back()
                ur._send_program(time.monotonic(), force=True)
            else:
                ur._channel.take_back()
                ur._program.expect(time.monotonic())
                reply = await (await ur._dashboard_link()).command(dash.Play())
                if not reply.success:
                    raise BackendError(f"play refused: {reply.text}")

    @contextlib.asynccontextmanager
    async def _exclusive(self, what: str) -> AsyncIterator[None]:
        """Run a start-up or program restart alone: refuse (BackendError) while one is under way."""
        if self._lock.locked():
            raise BackendError(f"a start-up or program restart is already under way: {what} refused")
        async with self._lock:
            yield
