"""``unlock protective stop`` within 5 s of the stop (issue 33, point 8).

UR's dashboard guide answers ``Cannot unlock protective stop until 5s after occurrence. Always inspect
cause of protective stop before unlocking`` to an unlock sooner than 5 s after the stop. urcl's URSim
tests send the primary interface's ``set unlock protective stop`` straight after a stop and wait up to
5 s (its default) for the stop to clear, so the fake carries that one out once the 5 s are over.

Reproduction on the old fake: it unlocked as soon as the arm rested (the dashboard answered
``Protective stop releasing`` a few cycles after the stop, the primary command cleared it at once).
"""

from __future__ import annotations

import asyncio

import pytest

from tests.fakeur.test_controller import Link
from tests.fakeur.test_controller_life import ManualClock, manual_fake
from urdaemon.fakeur.controller import FakeController
from urdaemon.fakeur.life import UNLOCK_TOO_SOON, UNLOCK_WAIT_S, ArmLife
from urdaemon.model import SafetyMode
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import primary as prim
from urdaemon.protocols._buffer import Side

pytestmark = pytest.mark.timeout(60)

DT = 0.002
WAIT_CYCLES = round(UNLOCK_WAIT_S / DT)


def _mode(life: ArmLife) -> SafetyMode:
    """The safety mode, read afresh (not narrowed by an earlier assert)."""
    return life.safety_mode


def test_the_life_refuses_an_unlock_for_5_s_of_controller_time() -> None:
    life = ArmLife(powered=True)
    life.advance(10.0)
    life.protective_stop()
    assert life.unlockable_at == pytest.approx(10.0 + UNLOCK_WAIT_S)
    life.advance(14.99)
    assert life.unlock_protective_stop(moving=False) == UNLOCK_TOO_SOON
    assert life.safety_mode is SafetyMode.PROTECTIVE_STOP
    life.advance(15.0)
    assert life.unlock_protective_stop(moving=False) is None
    assert _mode(life) is SafetyMode.NORMAL


async def _at_rest_after_a_stop(controller: FakeController, clock: ManualClock) -> None:
    controller.protective_stop()
    clock.until(lambda: not any(controller.arm.qd))
    assert controller.arm.timestamp < controller.arm.life.unlockable_at


async def test_the_dashboard_refuses_with_ur_s_text_then_unlocks() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        link = await Link.open(dash.DashboardConnection(Side.DAEMON), controller.address, 29999)
        await link.next(dash.Banner)
        await _at_rest_after_a_stop(controller, clock)
        await link.send(dash.UnlockProtectiveStop())
        early = await link.next(dash.CommandReply)
        assert early.success is False
        assert early.text == UNLOCK_TOO_SOON
        assert _mode(controller.arm.life) is SafetyMode.PROTECTIVE_STOP
        clock.until(lambda: controller.arm.timestamp >= controller.arm.life.unlockable_at, WAIT_CYCLES + 10)
        await link.send(dash.UnlockProtectiveStop())
        late = await link.next(dash.CommandReply)
        assert (late.success, late.text) == (True, "Protective stop releasing")
        assert _mode(controller.arm.life) is SafetyMode.NORMAL
        link.close()


async def test_the_primary_unlock_sent_early_is_carried_out_once_the_5_s_are_over() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        link = await Link.open(prim.PrimaryConnection(Side.DAEMON), controller.address, 30001)
        await link.next(prim.VersionMessage)
        await _at_rest_after_a_stop(controller, clock)
        link.writer.write(b"set unlock protective stop\n")
        await link.writer.drain()
        arm = controller.arm
        due = arm.life.unlockable_at
        unlocked_at = None
        for _ in range(WAIT_CYCLES + 50):  # one cycle and one event-loop turn at a time
            clock.turn(1)
            await asyncio.sleep(0)
            if arm.safety_mode is SafetyMode.NORMAL:
                unlocked_at = arm.timestamp
                break
        assert unlocked_at is not None, "the early unlock was never carried out"
        assert unlocked_at >= due - 1e-9, "unlocked before the 5 s were over"
        assert unlocked_at <= due + 2 * DT, "not carried out when the 5 s were over"
        link.close()
