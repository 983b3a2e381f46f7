"""One clock for every fake controller in a process (``SharedClock``): each ticks in its slot."""

from __future__ import annotations

import asyncio
from collections.abc import Callable

from urdaemon.backends.clock import TickClock, tick_clock

__all__ = ["SharedClock"]


class SharedClock:
    """One clock for every fake controller in a process, instead of one each.

    ``slots`` spreads the controllers over the period: slot ``k`` ticks ``k·period/slots`` after
    slot 0, so with one controller per slot each sends its RTDE packages at its own phase, as
    independent controllers do (the daemon sees one package at a time, the worst case for it).
    With one slot every controller ticks in the same loop callback and their packages leave in
    one burst (cheapest for the fake: one wake-up per period for the whole cell).

    The clock is ``tick_clock``'s: a timerfd the loop wakes on (Linux), else a timing thread. A
    stall of up to one period does not cost any controller its package: each slot whose time
    passed still ticks, late and in order (``catch_up``); beyond that, cycles are skipped, as a
    controller that was not running would skip them.
    """

    def __init__(self, period: float, slots: int = 1) -> None:
        if slots < 1:
            raise ValueError(f"slots must be at least 1, got {slots}")
        self.period = period
        self.slots: list[list[Callable[[], None]]] = [[] for _ in range(slots)]
        self._next = 0
        self._clock: TickClock | None = None

    def add(self, tick: Callable[[], None], slot: int, loop: asyncio.AbstractEventLoop) -> None:
        """Tick ``tick`` once per period in ``slot`` (modulo the slot count); starts the clock."""
        self.slots[slot % len(self.slots)].append(tick)
        if self._clock is None:
            self._clock = tick_clock(
                self.period / len(self.slots), self._fire, loop, catch_up=len(self.slots)
            )
            self._clock.start()

    def remove(self, tick: Callable[[], None]) -> None:
        """Stop ticking ``tick``; the clock stops with the last one."""
        for ticks in self.slots:
            if tick in ticks:
                ticks.remove(tick)
        if self._clock is not None and not any(self.slots):
            self._clock.stop()
            self._clock = None

    def _fire(self) -> None:
        ticks = self.slots[self._next]
        self._next = (self._next + 1) % len(self.slots)
        for tick in ticks:
            tick()
