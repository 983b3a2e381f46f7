"""A fake controller's clock that waits for the daemon's answer (``LockstepClock``).

A fake on its own clock ticks in real time whatever the daemon does: on a busy machine the daemon's
servoj for one cycle can arrive after the fake's next cycle, and the arm then holds the old target
for a cycle and jumps the next, as a real controller does with a late host. That is right for the
fake, but a test that measures the motion a punctual daemon commands (speed, acceleration and jerk
every cycle) then measures the machine's load instead. On this clock the fake's time waits for the
daemon: while ``follow()`` holds, a cycle runs only once the daemon has answered the last one
(``answered()``), and never sooner than the real period after the previous tick; otherwise the fake
ticks in real time, as on ``SharedClock``. A daemon that does not answer within ``hold`` periods of
real time costs the clock its lockstep until its next answer (``unanswered`` counts those cycles),
so a daemon that has stopped writing frames never stops the fake.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable

from urdaemon.fakeur.shared_clock import SharedClock

__all__ = ["LockstepClock"]


class LockstepClock(SharedClock):
    """One slot; ticks on the real period, holds each cycle until the daemon answered the last."""

    def __init__(self, period: float, hold: int = 500) -> None:
        super().__init__(period)
        self.hold = hold
        """Real periods a cycle waits for the daemon's answer before it runs unanswered."""
        self.follow: Callable[[], bool] = lambda: False
        """Whether the daemon answers every cycle now (the test sets it once the daemon exists)."""
        self.unanswered = 0
        """Cycles that ran without the daemon's answer to the one before while following."""
        self.last_answered = False
        """Whether the daemon answered the cycle before the one now running."""
        self._seen = False  # an answer since the last cycle
        self._awaiting = False  # the next cycle waits for an answer
        self._suspended = False  # a wait ran out: no waiting until the next answer
        self._held = 0
        self._pending = False
        self._loop: asyncio.AbstractEventLoop | None = None

    def add(self, tick: Callable[[], None], slot: int, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        super().add(tick, 0, loop)

    def answered(self) -> None:
        """The daemon wrote its answer to the last cycle: a cycle held for it runs now."""
        self._seen = True
        self._suspended = False
        if not self._awaiting:
            return
        self._awaiting = False
        if self._held and not self._pending and self._loop is not None:
            self._pending = True
            self._loop.call_soon(self._run_cycle)

    def _fire(self) -> None:
        if self._pending:
            return
        if self._awaiting:
            self._held += 1
            if self._held < self.hold:
                return
            self.unanswered += 1
            self._suspended = True
        self._run_cycle()

    def _run_cycle(self) -> None:
        self._pending = False
        self._held = 0
        self.last_answered, self._seen = self._seen, False
        self._awaiting = not self._suspended and self.follow()
        super()._fire()
