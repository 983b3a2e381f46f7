"""Scripts on the primary, secondary and real-time interfaces run in the URScript interpreter, the way
a controller runs them (the fake's clock turned by hand; messages read off the primary interface)."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

import pytest

from tests.fakeur.test_controller import Link
from tests.fakeur.test_controller_life import ManualClock, manual_fake
from urdaemon.fakeur.controller import FakeController
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import primary as prim
from urdaemon.protocols._buffer import Side

pytestmark = pytest.mark.timeout(60)

LOOP = "def {name}():\n  while True:\n    sync()\n  end\nend\n"


async def _eventually(controller: FakeController, done: Callable[[], bool]) -> None:
    """Until the fake's reader task has handled what was sent and its scripts were compiled: woken by
    those events, with no cycle run meanwhile (the clock is turned by hand)."""
    await controller.until(done, cycles=0)


async def _send(controller: FakeController, port: int, text: str) -> None:
    _, writer = await asyncio.open_connection(controller.address, port)
    writer.write(text.encode("ascii"))
    await writer.drain()
    writer.close()


def _running(controller: FakeController) -> object:
    """The program the fake runs (a function: mypy would otherwise narrow the attribute for good)."""
    return controller.programs.main


async def _primary(controller: FakeController) -> Link:
    link = await Link.open(prim.PrimaryConnection(Side.DAEMON), controller.address, 30001)
    await link.next(prim.VersionMessage)
    return link


async def _message(link: Link, kind: type[Any], clock: ManualClock) -> Any:
    clock.turn(1)
    return await link.next(kind)


@pytest.mark.parametrize("port", [30002, 30003])
async def test_a_bare_urscript_line_runs_as_a_program(port: int) -> None:
    """Reproduction (python-urx): ``set_digital_out(2, True)`` on 30002 was refused as an unknown
    controller command, and 30003 did not exist."""
    async with manual_fake(powered=True) as (controller, clock):
        await _send(controller, port, "set_digital_out(2, True)\n")
        await _eventually(controller, lambda: controller.programs.name is not None)
        clock.turn(3)
        assert controller.arm.io.digital_out & (1 << 2)


async def test_a_def_program_replaces_the_running_one_and_a_sec_program_runs_beside_it() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        link = await _primary(controller)
        await _send(controller, 30001, LOOP.format(name="first"))
        started = await link.next(prim.KeyMessage)
        assert (started.title, started.text) == ("PROGRAM_XXX_STARTED", "first")
        clock.turn(5)
        await _send(controller, 30001, "sec beside():\n  set_digital_out(3, True)\nend\n")
        await _eventually(controller, lambda: bool(controller.programs.secondary))
        clock.turn(2)
        assert controller.arm.io.digital_out & (1 << 3)
        assert controller.programs.name == "first"
        await _send(controller, 30002, LOOP.format(name="second"))
        stopped = await link.next(prim.KeyMessage)
        assert (stopped.title, stopped.text) == ("PROGRAM_XXX_STOPPED", "first")
        started = await link.next(prim.KeyMessage)
        assert (started.title, started.text) == ("PROGRAM_XXX_STARTED", "second")
        await _send(controller, 30001, "stop program\n")
        stopped = await link.next(prim.KeyMessage)
        assert (stopped.title, stopped.text) == ("PROGRAM_XXX_STOPPED", "second")
        assert controller.programs.main is None
        link.close()


async def test_a_compile_error_names_line_and_column_and_nothing_starts() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        link = await _primary(controller)
        await _send(controller, 30001, "def broken():\n  textmsg(1)\n  no_such_function(2)\nend\n")
        error = await link.next(prim.RuntimeExceptionMessage)
        assert error.line == 3
        assert error.column > 0
        assert "no_such_function" in error.text
        clock.turn(5)
        assert controller.programs.main is None
        assert controller.programs.name is None
        link.close()


async def test_a_runtime_error_names_its_line_and_stops_the_program() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        link = await _primary(controller)
        await _send(controller, 30001, "def failing():\n  sync()\n  x = [1, 2]\n  y = x[7]\nend\n")
        await link.next(prim.KeyMessage)  # started
        clock.turn(3)
        error = await link.next(prim.RuntimeExceptionMessage)
        assert error.line == 4, error
        stopped = await link.next(prim.KeyMessage)
        assert (stopped.title, stopped.text) == ("PROGRAM_XXX_STOPPED", "failing")
        assert controller.programs.main is None
        link.close()


async def test_textmsg_and_popup_become_primary_messages() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        link = await _primary(controller)
        await _send(controller, 30001, 'def talk():\n  textmsg("hello ", 42)\n  popup("look")\nend\n')
        await link.next(prim.KeyMessage)
        text = await _message(link, prim.TextMessage, clock)
        assert text.text == "hello 42"
        popup = await link.next(prim.OtherRobotMessage)
        assert popup.type == prim.RobotMessageType.POPUP
        assert popup.body.endswith(b"look")
        link.close()


async def test_a_paused_program_is_not_stepped_and_resumes_where_it_was() -> None:
    program = (
        "def count():\n  i = 0\n  while True:\n    i = i + 1\n"
        "    write_output_integer_register(0, i)\n    sync()\n  end\nend\n"
    )
    async with manual_fake(powered=True, urcap=("127.0.0.1", 9)) as (controller, clock):
        await _send(controller, 30001, program)
        await _eventually(controller, lambda: controller.programs.main is not None)
        clock.turn(10)
        counted = controller.arm.io.registers_int[0]
        assert counted == 10
        link = await Link.open(dash.DashboardConnection(Side.DAEMON), controller.address, 29999)
        await link.next(dash.Banner)
        await link.send(dash.Pause())
        assert (await link.next(dash.CommandReply)).success
        clock.turn(10)
        assert controller.arm.io.registers_int[0] == counted
        await link.send(dash.Play())
        assert (await link.next(dash.CommandReply)).success
        clock.turn(10)
        assert controller.arm.io.registers_int[0] == counted + 10
        link.close()


async def test_an_rtde_watchdog_stops_the_program_when_its_input_stops_arriving() -> None:
    program = (
        'def watched():\n  rtde_set_watchdog("input_int_register_0", 10, "stop")\n'
        "  while True:\n    sync()\n  end\nend\n"
    )
    async with manual_fake(powered=True) as (controller, clock):
        link = await _primary(controller)
        await _send(controller, 30001, program)
        await link.next(prim.KeyMessage)  # started
        clock.turn(40)  # 80 ms < 100 ms: still running
        assert controller.programs.main is not None
        controller.rtde.apply_inputs({"input_int_register_0": 1})  # what an RTDE input package does
        clock.turn(40)
        assert controller.programs.main is not None
        clock.turn(20)  # 120 ms since the last input
        assert controller.programs.name == "watched"
        assert _running(controller) is None
        warning = await link.next(prim.TextMessage)
        assert "input_int_register_0" in warning.text
        link.close()
