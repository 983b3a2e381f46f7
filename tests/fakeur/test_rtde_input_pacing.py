"""The fake takes RTDE input packages as a controller does: while it keeps time, as they arrive (the
last write of a cycle wins); after it was held up, or when it read together packages an output it
sent meanwhile may have released, one per client per cycle, in arrival order (the fake's clock turned
by hand, its wall clock too: the packages arrive between two cycles)."""

from __future__ import annotations

import pytest

from tests.fakeur.test_controller import Link
from tests.fakeur.test_controller_life import ManualClock, manual_fake
from urdaemon.fakeur.controller import FakeController
from urdaemon.fakeur.rtde_service import MAX_PENDING_INPUTS
from urdaemon.protocols import primary as prim
from urdaemon.protocols import rtde
from urdaemon.protocols._buffer import Side

pytestmark = pytest.mark.timeout(60)


class Wall:
    """The fake's wall clock, moved by hand (``held_up``: as if the fake's process did not run)."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now

    def held_up(self, seconds: float = 0.05) -> None:
        self.now += seconds


MIRROR = (
    "def mirror():\n  while True:\n"
    "    write_output_integer_register(0, read_input_integer_register(0))\n    sync()\n  end\nend\n"
)
"""A program that shows, every cycle, what it reads of input_int_register_0."""


async def _mirroring(controller: FakeController, clock: ManualClock, frequency: float = 10.0) -> Link:
    """The mirror program running, and an RTDE client owning input_int_register_0 (its outputs at
    ``frequency``)."""
    primary = await Link.open(prim.PrimaryConnection(Side.DAEMON), controller.address, 30001)
    await primary.next(prim.VersionMessage)
    await primary.send(prim.Script(MIRROR))
    started = await primary.next(prim.KeyMessage)
    assert (started.title, started.text) == ("PROGRAM_XXX_STARTED", "mirror")
    primary.close()
    link = await Link.open(rtde.RtdeConnection(Side.DAEMON), controller.address, 30004)
    await link.send(rtde.RequestProtocolVersion(2))
    assert (await link.next(rtde.ProtocolVersionReply)).accepted
    await link.send(rtde.SetupInputs(("input_int_register_0",)))
    configured = await link.next(rtde.InputsConfigured)
    assert configured.recipe_id == 1
    assert not configured.in_use
    await link.send(rtde.SetupOutputs(frequency, ("timestamp",)))
    await link.next(rtde.OutputsConfigured)
    await _start(link)
    clock.turn(2)
    assert controller.arm.io.registers_int.get(0, 0) == 0
    return link


def _queue(link: Link, values: list[int]) -> None:
    """``values`` as input packages, encoded and not yet written."""
    for value in values:
        link.conn.send(rtde.InputData((value,), recipe_id=1))


async def _arrive_together(link: Link, values: list[int]) -> None:
    """``values`` as input packages in one write, then wait until the fake has read them all (its
    reply to the pause request that follows them); no cycle runs meanwhile."""
    _queue(link, values)
    link.conn.send(rtde.Pause())
    link.writer.write(link.conn.data_to_send())
    await link.writer.drain()
    assert (await link.next(rtde.PauseReply)).accepted


async def _start(link: Link) -> None:
    """Start the client's outputs (again, after ``_arrive_together``'s pause request)."""
    await link.send(rtde.Start())
    assert (await link.next(rtde.StartReply)).accepted


async def test_two_input_packages_in_one_cycle_reach_the_program_in_turn() -> None:
    """Reproduction: ur_rtde's speedj package and its first watchdog kick arrived while the fake was
    held up; the fake applied both at once, so its program never read the speedj command (the arm
    stood still while the program ran). The program must see the first, then the second."""
    wall = Wall()
    async with manual_fake(powered=True, wall_clock=wall) as (controller, clock):
        link = await _mirroring(controller, clock)
        wall.held_up()
        await _arrive_together(link, [7, 8])
        assert controller.input_registers.ints[0] == 7  # the first applies at once, as before
        clock.turn(1)
        assert controller.arm.io.registers_int[0] == 7
        clock.turn(1)
        assert controller.arm.io.registers_int[0] == 8
        clock.turn(3)
        assert controller.arm.io.registers_int[0] == 8
        link.close()


async def test_a_client_far_ahead_loses_no_package_and_catches_up_within_the_bound() -> None:
    """More packages than the queue holds: the first is applied at once, the oldest waiting ones too
    as room is needed, the rest one per cycle, so the program sees the last MAX_PENDING_INPUTS + 1 in
    order and reaches the latest within that many cycles."""
    wall = Wall()
    async with manual_fake(powered=True, wall_clock=wall) as (controller, clock):
        link = await _mirroring(controller, clock)
        wall.held_up()
        values = list(range(1, MAX_PENDING_INPUTS + 6))
        await _arrive_together(link, values)
        seen = []
        for _ in range(MAX_PENDING_INPUTS + 3):
            clock.turn(1)
            seen.append(controller.arm.io.registers_int[0])
        assert seen == values[-MAX_PENDING_INPUTS - 1 :] + [values[-1]] * 2
        link.close()


async def test_a_client_faster_than_the_cycles_never_falls_behind_a_fake_that_keeps_time() -> None:
    """Reproduction: a client sending several packages per cycle to a fake that kept time built a
    queue applied one per cycle, so its program ran MAX_PENDING_INPUTS cycles behind for as long as it
    sent. A controller applies what arrived by the next cycle: the last write wins."""
    wall = Wall()
    async with manual_fake(powered=True, wall_clock=wall) as (controller, clock):
        link = await _mirroring(controller, clock)
        for first in range(1, 30, 3):
            await _arrive_together(link, [first, first + 1, first + 2])
            assert controller.input_registers.ints[0] == first + 2
            wall.now += controller.step_time
            clock.turn(1)
            assert controller.arm.io.registers_int[0] == first + 2
            await _start(link)  # (each arrival ends with a pause request)
        link.close()


def _write(link: Link, values: list[int]) -> None:
    """``values`` as input packages, into the socket at once; nothing awaited, so the fake (on this
    loop) does not read them before the test next awaits."""
    _queue(link, values)
    link.writer.write(link.conn.data_to_send())


async def test_a_package_an_output_released_while_the_fake_had_not_read_the_one_before_waits() -> None:
    """Reproduction (the side-by-side stress run, ur_rtde's watchdog judge): ur_rtde's speedj package
    sat unread in the fake's socket while the fake, held up by less than a period, ran a cycle; that
    cycle's output package acknowledged it, and the acknowledgement let ur_rtde's TCP send the
    watchdog kick it was holding back (Nagle: ur_rtde sets TCP_NODELAY, then boost::asio::connect
    opens a new socket). The fake, on time by its wall clock, read both at once and applied both,
    so its program never read speedj. On a controller the kick comes after that output, in the next
    cycle: the program must see the first package, then the second."""
    wall = Wall()
    async with manual_fake(powered=True, wall_clock=wall) as (controller, clock):
        link = await _mirroring(controller, clock, frequency=500.0)
        _write(link, [7])
        wall.now += controller.step_time
        clock.turn(1)  # a cycle on time: its output goes to the client while 7 waits unread
        assert controller.arm.io.registers_int.get(0, 0) == 0
        await _arrive_together(link, [8])  # the package that output released, read with 7
        assert controller.input_registers.ints[0] == 7
        wall.now += controller.step_time
        clock.turn(1)
        assert controller.arm.io.registers_int[0] == 7
        clock.turn(1)
        assert controller.arm.io.registers_int[0] == 8
        link.close()


async def test_packages_read_one_at_a_time_in_a_cycle_after_an_output_still_end_on_the_last() -> None:
    """The other side of that rule: a client streaming at the controller's rate that sends two
    packages in one cycle, each read on its own (the fake keeps time), has the last write win, as on a
    controller; neither waits for a later cycle."""
    wall = Wall()
    async with manual_fake(powered=True, wall_clock=wall) as (controller, clock):
        link = await _mirroring(controller, clock, frequency=500.0)
        for first in range(1, 20, 2):
            wall.now += controller.step_time
            clock.turn(1)
            await _arrive_together(link, [first])
            await _start(link)  # (each arrival ends with a pause request)
            await _arrive_together(link, [first + 1])
            assert controller.input_registers.ints[0] == first + 1
            await _start(link)
            wall.now += controller.step_time
            clock.turn(1)
            assert controller.arm.io.registers_int[0] == first + 1
        link.close()
