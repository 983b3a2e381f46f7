"""urcl's ``PrimaryClient::sendScriptBlocking`` against the fake: each case urcl's URSim tests name.

urcl decides from the primary interface alone (src/primary/primary_client.cpp): before sending it
requires the robot mode of the latest ROBOT_MODE_DATA to be RUNNING and the latest SAFETY_MODE message
to allow running (NORMAL, REDUCED, RECOVERY, or none yet); after sending it fails on a
RUNTIME_EXCEPTION message, on an ERROR_CODE of level VIOLATION/FAULT/CRITICAL_FAULT (then it sends
``stop program``) or WARNING (unless told to ignore warnings), and on no PROGRAM_XXX_STARTED key
message naming the script within the start timeout; it succeeds on PROGRAM_XXX_STOPPED naming the
script, once 100 ms more brought no error. It waits for that STOPPED without a bound, so a fake that
never sends it hangs the client. ``UrclScript`` below is that logic, ported, on the fake's clock:
one poll is one robot state (100 ms of controller time), so the decision is urcl's, in controller time.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import pytest

from tests.fakeur.test_controller import Link
from tests.fakeur.test_controller_life import ManualClock, manual_fake
from urdaemon.fakeur.controller import STATE_PERIOD_S, FakeController
from urdaemon.fakeur.life import UNLOCK_WAIT_S
from urdaemon.model import RobotMode, SafetyMode
from urdaemon.protocols import primary as prim
from urdaemon.protocols._buffer import Side

pytestmark = pytest.mark.timeout(90)

_ALLOWED = {SafetyMode.NORMAL, SafetyMode.REDUCED, SafetyMode.RECOVERY, SafetyMode.UNDEFINED_SAFETY_MODE}
_ERRORS = {prim.ReportLevel.VIOLATION, prim.ReportLevel.FAULT, prim.ReportLevel.CRITICAL_FAULT}
START_TIMEOUT_POLLS = 10
"""urcl's default start timeout, 1 s, in robot states."""
HANG_POLLS = 300
"""30 s of controller time after the start with no STOPPED: urcl would still be waiting."""


@dataclass
class UrclScript:
    """One urcl primary client: what it has heard, and ``send_script_blocking``'s verdict."""

    controller: FakeController
    clock: ManualClock
    link: Link
    mode_data: prim.RobotModeData | None = None
    safety_mode: int = SafetyMode.UNDEFINED_SAFETY_MODE
    errors: list[prim.ErrorCodeMessage] = field(default_factory=list)
    keys: list[prim.KeyMessage] = field(default_factory=list)
    runtime: prim.RuntimeExceptionMessage | None = None
    commands: list[str] = field(default_factory=list)
    """Controller commands it sent on its own (``stop program`` after an error)."""

    async def poll(self) -> None:
        """100 ms of controller time, then everything the fake said up to its latest robot state."""
        self.clock.turn(round(STATE_PERIOD_S / self.controller.step_time))
        while True:
            event = await self.link.next()
            if isinstance(event, prim.RobotState):
                self.mode_data = event.get(prim.RobotModeData) or self.mode_data
                return
            if isinstance(event, prim.SafetyModeMessage):
                self.safety_mode = event.safety_mode
            elif isinstance(event, prim.ErrorCodeMessage):
                self.errors.append(event)
            elif isinstance(event, prim.KeyMessage):
                self.keys.append(event)
            elif isinstance(event, prim.RuntimeExceptionMessage):
                self.runtime = event

    async def write(self, text: str) -> None:
        self.link.writer.write(text.encode() + b"\n")
        await self.link.writer.drain()

    async def send(self, text: str) -> None:
        """Send a script and wait (no controller time) until the fake compiled and started or refused it."""
        programs = self.controller.programs
        await self.write(text)
        await self.controller.until(lambda: programs.busy, cycles=0, timeout=10)
        await programs.settled()

    async def command(self, line: str, *, until: Any, polls: int = 100) -> None:
        """A controller command (``power on``...), then polls until ``until(self)`` holds."""
        await self.write(line)
        for _ in range(polls):
            await self.poll()
            if until(self):
                return
        raise AssertionError(f"{line!r}: not done within {polls} polls")

    async def run(self, body: str, name: str, *, fail_on_warnings: bool = True) -> str:
        """urcl's verdict on ``body`` wrapped as ``def name():``: "ok" or the exception urcl throws."""
        if self.mode_data is None:
            await self.poll()
        assert self.mode_data is not None
        if self.mode_data.robot_mode != RobotMode.RUNNING:
            return "RobotModeException"
        if self.safety_mode not in _ALLOWED:
            return "SafetyModeException"
        self.forget()
        lines = "".join(f"  {line}\n" for line in body.splitlines())
        await self.send(f"def {name}():\n{lines}end\n")
        started, stopped_at = False, None
        for polled in range(HANG_POLLS):
            await self.poll()
            if self.runtime is not None:
                return "RobotRuntimeException"
            errors, self.errors = self.errors, []
            if any(e.report_level in _ERRORS for e in errors):
                self.commands.append("stop program")
                await self.write("stop program")
                return "RobotErrorCodeException"
            if fail_on_warnings and any(e.report_level == prim.ReportLevel.WARNING for e in errors):
                return "RobotErrorCodeException"
            for key in self.keys:
                if key.text == name and key.title == "PROGRAM_XXX_STOPPED" and stopped_at is None:
                    stopped_at, started = polled, True
                elif key.text == name and key.title == "PROGRAM_XXX_STARTED":
                    started = True
            self.keys = []
            if stopped_at is not None and polled > stopped_at:  # 100 ms drained after STOPPED
                return "ok"
            if not started and polled >= START_TIMEOUT_POLLS:
                return "TimeoutException"
        return "hangs"

    def forget(self) -> None:
        """What urcl clears before it sends: the last runtime exception, error codes, key messages."""
        self.runtime, self.errors, self.keys = None, [], []

    async def unlock_protective_stop(self) -> None:
        """urcl's ``commandUnlockProtectiveStop`` (it waits 5 s): ``is_protective_stopped`` turns False."""
        await self.command(
            "set unlock protective stop",
            until=lambda c: not c.mode_data.is_protective_stopped,
            polls=round(UNLOCK_WAIT_S / STATE_PERIOD_S) + 5,
        )


async def _client(controller: FakeController, clock: ManualClock) -> UrclScript:
    link = await Link.open(prim.PrimaryConnection(Side.DAEMON), controller.address, 30001)
    await link.next(prim.VersionMessage)
    return UrclScript(controller, clock, link)


# ---- urcl's tests (tests/test_primary_client.cpp), case by case --------------------------------------


async def test_happy_path() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        urcl = await _client(controller, clock)
        assert await urcl.run('textmsg("still running")\nsleep(0.1)\nsync()', "test_fun") == "ok"
        urcl.link.close()


async def test_fails_on_a_robot_that_is_not_running() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        urcl = await _client(controller, clock)
        await urcl.command("power off", until=lambda c: c.mode_data.robot_mode == RobotMode.POWER_OFF)
        assert await urcl.run('textmsg("Still running")', "a") == "RobotModeException"
        await urcl.command("power on", until=lambda c: c.mode_data.robot_mode == RobotMode.IDLE)
        assert await urcl.run('textmsg("Still running")', "b") == "RobotModeException"
        await urcl.command("set robotmode run", until=lambda c: c.mode_data.robot_mode == RobotMode.RUNNING)
        assert await urcl.run('textmsg("Still running")', "c") == "ok"
        urcl.link.close()


async def test_fails_on_a_bad_safety_mode() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        urcl = await _client(controller, clock)
        assert await urcl.run("protective_stop()", "a") == "RobotErrorCodeException"
        await urcl.poll()
        assert await urcl.run('textmsg("Still running")', "b") == "SafetyModeException"
        await urcl.unlock_protective_stop()
        assert await urcl.run('textmsg("Still running")', "c") == "ok"
        urcl.link.close()


async def test_ignoring_warnings_a_protective_stop_script_ends() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        urcl = await _client(controller, clock)
        assert await urcl.run("protective_stop()", "a", fail_on_warnings=False) == "ok"
        await urcl.unlock_protective_stop()
        urcl.link.close()


async def test_fails_on_a_runtime_exception() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        urcl = await _client(controller, clock)
        assert await urcl.run("movej(p[10,0,0,0,0,0])", "a") == "RobotRuntimeException"
        urcl.link.close()


async def test_fails_on_robot_errors_then_moves_after_the_unlock() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        urcl = await _client(controller, clock)
        assert await urcl.run("movel(p[10,0,0,0,0,0])", "a") == "RobotErrorCodeException"
        await urcl.unlock_protective_stop()
        assert await urcl.run("movej([0.5,-0.5,0.5,0,0,0])", "b") == "ok"
        urcl.link.close()


async def test_fails_on_a_bad_script() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        urcl = await _client(controller, clock)
        assert await urcl.run("non_existing_func()", "a") == "RobotRuntimeException"
        assert await urcl.run("calldoesntexist()", "illegal_fun") == "RobotRuntimeException"
        urcl.link.close()


# ---- stops urcl's own checks cannot see: a client that connected after the stop -----------------------


async def test_a_client_connected_during_a_protective_stop_fails_by_its_start_timeout() -> None:
    """SAFETY_MODE comes on changes only, so a client that connects during a protective stop knows no
    safety mode and sends. The fake refuses to start the program (a text message says why; no
    PROGRAM_XXX_STARTED), so urcl reports failure when its start timeout ends, not success."""
    async with manual_fake(powered=True) as (controller, clock):
        first = await _client(controller, clock)
        assert await first.run("protective_stop()", "a") == "RobotErrorCodeException"
        late = await _client(controller, clock)
        await late.poll()
        assert late.safety_mode == SafetyMode.UNDEFINED_SAFETY_MODE
        assert late.mode_data is not None
        assert late.mode_data.is_protective_stopped
        assert await late.run('textmsg("Still running")', "b") == "TimeoutException"
        assert controller.programs.name != "b"
        await late.unlock_protective_stop()
        assert await late.run('textmsg("Still running")', "c") == "ok"
        first.link.close()
        late.link.close()


async def test_an_emergency_stop_fails_on_the_robot_mode() -> None:
    """An emergency stop powers the arm off: urcl refuses on the robot mode before sending, whether
    or not it saw the SAFETY_MODE message (ROBOT_EMERGENCY_STOP, which it refuses too)."""
    async with manual_fake(powered=True) as (controller, clock):
        urcl = await _client(controller, clock)
        controller.emergency_stop()
        await urcl.poll()
        assert urcl.safety_mode == SafetyMode.ROBOT_EMERGENCY_STOP
        assert await urcl.run('textmsg("Still running")', "a") == "RobotModeException"
        late = await _client(controller, clock)
        assert await late.run('textmsg("Still running")', "b") == "RobotModeException"
        urcl.link.close()
        late.link.close()
