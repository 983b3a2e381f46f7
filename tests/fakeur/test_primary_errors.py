"""The primary interface's error paths as urcl reads them: SAFETY_MODE and ERROR_CODE robot messages.

urcl's ``PrimaryClient`` learns the safety mode only from SAFETY_MODE messages (UNDEFINED until the
first), and ``sendScriptBlocking`` fails on an ERROR_CODE (a warning such as C209, "A protective stop
was triggered", unless told to ignore warnings) and refuses to send while the safety mode is a stop.
URSim sends one C209A0 per ``protective_stop()`` (urcl's ``read_error_code``) and SAFETY_MODE on each
change (``test_read_safety_mode``).

Reproduction on the old fake: it never sent either message, so a client waiting for the error code
waited forever (these tests' ``next`` ran out of time) and the safety mode stayed UNDEFINED.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from tests.fakeur.test_controller import Link
from tests.fakeur.test_controller_life import manual_fake
from urdaemon.fakeur.life import UNLOCK_WAIT_S
from urdaemon.model import SafetyMode
from urdaemon.protocols import primary as prim
from urdaemon.protocols._buffer import Side

pytestmark = pytest.mark.timeout(60)

_PSTOP = (prim.ErrorCodeMessage, prim.SafetyModeMessage)

# ---- the robot side's reports, from a table -----------------------------------------------------------

REPORTS: list[tuple[list[SafetyMode], list[tuple[str, int]]]] = [
    ([SafetyMode.NORMAL], []),
    ([SafetyMode.PROTECTIVE_STOP], [("error", 209), ("mode", 3)]),
    ([SafetyMode.PROTECTIVE_STOP, SafetyMode.PROTECTIVE_STOP], [("error", 209), ("mode", 3)]),
    ([SafetyMode.PROTECTIVE_STOP, SafetyMode.NORMAL], [("error", 209), ("mode", 3), ("mode", 1)]),
    ([SafetyMode.ROBOT_EMERGENCY_STOP, SafetyMode.NORMAL], [("mode", 7), ("mode", 1)]),
    ([SafetyMode.REDUCED, SafetyMode.PROTECTIVE_STOP], [("mode", 2), ("error", 209), ("mode", 3)]),
    ([SafetyMode.FAULT], [("mode", 9)]),
]


def _kind(message: Any) -> tuple[str, int]:
    if isinstance(message, prim.ErrorCodeMessage):
        return ("error", message.code)
    assert isinstance(message, prim.SafetyModeMessage)
    return ("mode", message.safety_mode)


@pytest.mark.parametrize(("modes", "expected"), REPORTS)
def test_safety_reports_follow_the_mode(modes: list[SafetyMode], expected: list[tuple[str, int]]) -> None:
    reports = prim.SafetyReports()
    said = [message for mode in modes for message in reports.observe(mode)]
    assert [_kind(m) for m in said] == expected
    # every report crosses the wire as itself: robot side encodes, daemon side decodes
    robot, daemon = prim.PrimaryConnection(Side.ROBOT), prim.PrimaryConnection(Side.DAEMON)
    for message in said:
        robot.send(message)
    assert daemon.receive_data(robot.data_to_send()) == said


def test_the_protective_stop_error_is_c209_a0_a_warning_in_urcl_s_layout() -> None:
    robot = prim.PrimaryConnection(Side.ROBOT)
    robot.send(prim.protective_stop_error())
    data = robot.data_to_send()
    # [int32 length][uint8 20][uint64 ts][int8 source][uint8 6][int32 code][int32 arg][int32 level]...
    assert data[4] == prim.PackageType.ROBOT_MESSAGE
    assert data[14] == prim.RobotMessageType.ERROR_CODE
    assert int.from_bytes(data[15:19], "big") == 209
    assert int.from_bytes(data[19:23], "big") == 0
    assert int.from_bytes(data[23:27], "big") == prim.ReportLevel.WARNING
    assert data[35:] == b"A protective stop was triggered"


# ---- the fake, at the protocol level ----------------------------------------------------------------


async def _primary(address: str) -> Link:
    link = await Link.open(prim.PrimaryConnection(Side.DAEMON), address, 30001)
    await link.next(prim.VersionMessage)
    return link


async def _said(link: Link, kinds: tuple[type[Any], ...], count: int) -> list[Any]:
    return [await link.next(kinds) for _ in range(count)]


async def test_a_protective_stop_script_reports_c209_then_the_mode_and_the_unlock_normal() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        link = await _primary(controller.address)
        link.writer.write(b"def pstop():\n  protective_stop()\nend\n")
        await link.writer.drain()
        await controller.until(lambda: controller.programs.main is not None, cycles=0)
        clock.until(lambda: controller.arm.safety_mode is SafetyMode.PROTECTIVE_STOP)
        clock.turn(1)
        error, mode = await _said(link, _PSTOP, 2)
        assert isinstance(error, prim.ErrorCodeMessage), error
        assert (error.code, error.argument, error.report_level) == (209, 0, prim.ReportLevel.WARNING)
        assert isinstance(mode, prim.SafetyModeMessage), mode
        assert mode.safety_mode == SafetyMode.PROTECTIVE_STOP
        clock.until(lambda: not any(controller.arm.qd))
        link.writer.write(b"set unlock protective stop\n")
        await link.writer.drain()
        # carried out once 5 s of controller time have passed since the stop (fake-robot.md, "Errors")
        for _ in range(round(UNLOCK_WAIT_S / controller.step_time) + 50):
            clock.turn(1)
            await asyncio.sleep(0)  # the fake reads the command
            if controller.arm.safety_mode is SafetyMode.NORMAL:
                break
        clock.turn(1)
        (normal,) = await _said(link, _PSTOP, 1)  # no second error code: one per protective stop
        assert isinstance(normal, prim.SafetyModeMessage), normal
        assert normal.safety_mode == SafetyMode.NORMAL
        link.close()


async def test_an_emergency_stop_and_its_release_are_reported() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        link = await _primary(controller.address)
        controller.emergency_stop()
        clock.turn(1)
        (stopped,) = await _said(link, _PSTOP, 1)
        assert stopped == prim.SafetyModeMessage(0, 0, SafetyMode.ROBOT_EMERGENCY_STOP, 0, 0)
        controller.release_emergency_stop()
        clock.turn(1)
        (released,) = await _said(link, _PSTOP, 1)
        assert released.safety_mode == SafetyMode.NORMAL
        link.close()


async def test_nothing_is_reported_while_the_safety_mode_stays_normal() -> None:
    """urcl's ``test_read_safety_mode``: UNDEFINED right after connecting (only changes are sent)."""
    async with manual_fake(powered=True) as (controller, clock):
        link = await _primary(controller.address)
        clock.turn(60)  # past the 10 Hz state: robot states arrive, no safety report
        state = await link.next(prim.RobotState)
        assert state.get(prim.RobotModeData) is not None
        assert not [e for e in link.pending if isinstance(e, _PSTOP)]
        link.close()
