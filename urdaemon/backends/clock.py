"""A drift-free periodic clock for backends that have no robot to clock them (mock, servo)."""

from __future__ import annotations

import asyncio
import time

__all__ = ["PeriodicClock"]


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
