"""One timing thread for all fakes of a process: aligned or spread phases."""

from __future__ import annotations

import asyncio

import pytest

from tests.helpers import fake_address
from urdaemon.fakeur.command import share_clock
from urdaemon.fakeur.controller import FakeController
from urdaemon.fakeur.shared_clock import SharedClock

pytestmark = pytest.mark.timeout(30)


async def _ticks(clock: SharedClock, names: list[str], slots: list[int], count: int) -> list[str]:
    """Tick order of ``names`` on ``clock`` until ``count`` ticks happened."""
    loop = asyncio.get_running_loop()
    order: list[str] = []
    done = asyncio.Event()

    def tick_of(name: str) -> object:
        def tick() -> None:
            order.append(name)
            if len(order) >= count:
                done.set()

        return tick

    ticks = [tick_of(name) for name in names]
    for tick, slot in zip(ticks, slots, strict=True):
        clock.add(tick, slot, loop)  # type: ignore[arg-type]
    try:
        await asyncio.wait_for(done.wait(), 10.0)
    finally:
        for tick in ticks:
            clock.remove(tick)  # type: ignore[arg-type]
    return order[:count]


async def test_aligned_clock_ticks_every_fake_in_one_callback_in_order() -> None:
    clock = SharedClock(0.002, slots=1)
    order = await _ticks(clock, ["a", "b", "c"], [0, 1, 2], 9)
    assert order == ["a", "b", "c"] * 3


async def test_spread_clock_ticks_one_slot_per_sub_period() -> None:
    clock = SharedClock(0.002, slots=2)
    order = await _ticks(clock, ["a", "b"], [0, 1], 8)
    assert order in (["a", "b"] * 4, ["b", "a"] * 4)
    assert clock._clock is None  # the last remove stopped the clock


def test_share_clock_gives_each_fake_a_slot_and_refuses_mixed_rates() -> None:
    fakes = [FakeController("ur10e", address=fake_address()) for i in range(3)]
    spread = share_clock(fakes, "spread")
    assert spread is not None
    assert len(spread.slots) == 3
    assert [f._shared_clock for f in fakes] == [(spread, 0), (spread, 1), (spread, 2)]
    aligned = share_clock(fakes, "aligned")
    assert aligned is not None
    assert len(aligned.slots) == 1
    assert share_clock(fakes[:1], "spread") is None  # one fake keeps its own clock
    cb3 = FakeController("ur10", address=fake_address(), controller_version=(3, 15, 7, 0))
    with pytest.raises(ValueError, match="cannot tick"):
        cb3.use_clock(aligned, 0)
    with pytest.raises(ValueError, match="slots"):
        SharedClock(0.002, slots=0)
