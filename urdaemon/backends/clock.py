"""A drift-free periodic clock for backends that have no robot to clock them (mock, servo)."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable

__all__ = ["PeriodicClock", "ThreadClock"]


class PeriodicClock:
    """Wakes on an absolute grid of ``period`` seconds; counts late and skipped cycles."""

    def __init__(self, period: float, *, late_threshold: float | None = None) -> None:
        self.period = period
        self.late_threshold = period if late_threshold is None else late_threshold
        self._next = 0.0
        self.missed = 0
        self.late = 0
        self.max_lateness = 0.0

    def start(self) -> None:
        """Start the grid at the current time."""
        self._next = time.monotonic()

    async def wait(self) -> None:
        """Sleep until the next grid point; skip grid points that already passed by a whole cycle."""
        self._next += self.period
        now = time.monotonic()
        if now - self._next > self.period:
            skipped = int((now - self._next) / self.period)
            self.missed += skipped
            self._next += skipped * self.period
        delay = self._next - now
        await asyncio.sleep(delay if delay > 0.0 else 0.0)
        lateness = time.monotonic() - self._next
        if lateness > self.max_lateness:
            self.max_lateness = lateness
        if lateness > self.late_threshold:
            self.late += 1


class ThreadClock:
    """Calls ``tick()`` on the event loop every ``period`` seconds, timed by a thread.

    asyncio rounds timer waits up to whole milliseconds (epoll), so a 2 ms grid slips and then
    catches up in pairs; a thread sleeping to absolute deadlines (``time.sleep``, ~0.1 ms precise)
    hands evenly spaced ticks to the loop instead, at a few per cent of a core.
    """

    def __init__(self, period: float, tick: Callable[[], None], loop: asyncio.AbstractEventLoop) -> None:
        self.period = period
        self.missed = 0
        self._tick = tick
        self._loop = loop
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="urdaemon-clock", daemon=True)

    def start(self) -> None:
        """Start ticking."""
        self._thread.start()

    def stop(self) -> None:
        """Stop ticking (returns once the thread has ended)."""
        self._stop.set()
        self._thread.join(timeout=1.0)

    def _run(self) -> None:
        deadline = time.monotonic()
        while not self._stop.is_set():
            deadline += self.period
            now = time.monotonic()
            if now - deadline > self.period:  # the process was stopped or starved: skip, do not burst
                skipped = int((now - deadline) / self.period)
                self.missed += skipped
                deadline += skipped * self.period
            delay = deadline - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            try:
                self._loop.call_soon_threadsafe(self._tick)
            except RuntimeError:  # the loop closed
                return
