"""Cycle timing: a fixed-bin histogram of durations, and a rate-limited warning of missed cycles.

Both are cheap enough to run once per cycle at 500 Hz.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable

__all__ = ["LAG_LOG_INTERVAL_S", "Histogram", "LagLog"]

LAG_LOG_INTERVAL_S = 5.0
"""At most one missed/late-cycles warning per backend in this many seconds."""

BIN_NS = 1_000
"""Resolution: 1 µs."""
BINS = 20_000
"""Bins up to 20 ms; anything longer lands in the last bin (and still sets ``max``)."""


class Histogram:
    """Durations in nanoseconds; percentiles to the microsecond, the exact maximum."""

    def __init__(self) -> None:
        self._counts = [0] * BINS
        self.count = 0
        self.max_ns = 0

    def record(self, ns: int) -> None:
        """Add one duration (the 500 Hz path: an index, an increment, a comparison)."""
        i = ns // BIN_NS
        self._counts[i if 0 <= i < BINS else (BINS - 1 if i > 0 else 0)] += 1
        self.count += 1
        if ns > self.max_ns:
            self.max_ns = ns

    def reset(self) -> None:
        """Forget everything recorded."""
        self._counts = [0] * BINS
        self.count = 0
        self.max_ns = 0

    def percentile_us(self, fraction: float) -> float:
        """The upper edge (µs) of the bin of the ``fraction`` quantile, at most the maximum; 0.0 if empty."""
        if not 0.0 <= fraction <= 1.0:
            raise ValueError(f"fraction must be in [0, 1], got {fraction}")
        if self.count == 0:
            return 0.0
        rank = max(1, -(-self.count * fraction // 1))  # ceil, at least the first value
        seen = 0
        for i, n in enumerate(self._counts):
            seen += n
            if seen >= rank:  # the overflow bin has no upper edge but the maximum
                edge = (i + 1) * BIN_NS if i < BINS - 1 else self.max_ns
                return min(edge, self.max_ns) / 1_000.0
        return self.max_ns / 1_000.0  # pragma: no cover - the counts add up to count

    def summary(self) -> dict[str, float]:
        """count, median, p99, p99.9 and max in microseconds."""
        return {
            "count": self.count,
            "p50_us": self.percentile_us(0.5),
            "p99_us": self.percentile_us(0.99),
            "p999_us": self.percentile_us(0.999),
            "max_us": self.max_ns / 1_000.0,
        }


class LagLog:
    """Warns, at most once every ``interval_s``, that cycles were missed or late since the last warning.

    ``update(missed, late)`` takes the backend's running totals once per cycle: two integer
    comparisons while nothing changed; the first change is logged at once, later ones when the
    interval since the last line has passed (on the first cycle after it, even if no new cycle was
    missed then, so nothing counted stays unsaid).
    """

    __slots__ = ("_logged_late", "_logged_missed", "_next", "_since", "clock", "interval_s", "logger", "what")

    def __init__(
        self,
        what: str,
        logger: logging.Logger,
        *,
        interval_s: float = LAG_LOG_INTERVAL_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.what = what
        self.logger = logger
        self.interval_s = interval_s
        self.clock = clock
        """The time source (seconds); tests inject their own."""
        self._logged_missed = 0
        self._logged_late = 0
        self._next = -math.inf
        self._since: float | None = None

    def update(self, missed: int, late: int) -> None:
        """Take the totals of missed and late cycles; log a warning if due."""
        if missed == self._logged_missed and late == self._logged_late:
            return
        now = self.clock()
        if now < self._next:
            return
        new_missed = missed - self._logged_missed
        new_late = late - self._logged_late
        window = "" if self._since is None else f" in the last {now - self._since:.3g} s"
        self.logger.warning(
            "%s: %d cycles missed and %d late%s (%d missed, %d late in all): the machine or the event "
            "loop is too busy for this robot's rate",
            self.what,
            new_missed,
            new_late,
            window,
            missed,
            late,
        )
        self._logged_missed = missed
        self._logged_late = late
        self._since = now
        self._next = now + self.interval_s
