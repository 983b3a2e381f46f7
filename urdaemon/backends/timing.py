"""Cycle timing: a fixed-bin histogram of durations, and a warning of missed and late cycles that
speaks only when they matter for the backend (``LagLimits``), rate-limited, naming the likely cause.

Both are cheap enough to run once per cycle at 500 Hz.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from urdaemon.backends.lag_causes import LagCauses

__all__ = ["OWN_CLOCK_LAG", "UR_LAG", "Histogram", "LagLimits", "LagLog", "lag_limits", "ur_lag_limits"]

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


@dataclass(frozen=True, slots=True)
class LagLimits:
    """When missed and late cycles are worth a WARNING: a single hold-up of at least ``gap_s``, or
    more than ``fraction`` of the cycles of a ``window_s`` window missed or late; at most one line
    every ``interval_s``. Below both, they are only counted (``cycle_stats``, status, ``doctor``)."""

    gap_s: float
    fraction: float
    window_s: float
    interval_s: float


UR_LAG = LagLimits(gap_s=0.1, fraction=0.01, window_s=10.0, interval_s=60.0)
"""``ur``: a gap half of what the control program rides through before it stops the arm (by default
it holds a stream 100 cycles, 0.2 s at 500 Hz; the UR backend passes ``ur_lag_limits`` of its own
robot's), or more than 1 % of a 10 s window: the robot is about to stop, or its motion is rough."""

OWN_CLOCK_LAG = LagLimits(gap_s=0.5, fraction=0.25, window_s=30.0, interval_s=300.0)
"""``mock`` and ``servo``: the daemon's own clock drives them, so a missed cycle loses nothing
physical; only a half-second stall or a quarter of the cycles over 30 s (motion visibly jerky,
streams and viewers starved) is worth a line."""


def ur_lag_limits(stop_after_s: float) -> LagLimits:
    """The ``ur`` limits for a control program that stops after ``stop_after_s`` without a command:
    a gap of half of that warns."""
    return LagLimits(0.5 * stop_after_s, UR_LAG.fraction, UR_LAG.window_s, UR_LAG.interval_s)


def lag_limits(kind: str) -> LagLimits:
    """The default limits of a backend kind (``ur``; any other is driven by the daemon's clock)."""
    return UR_LAG if kind == "ur" else OWN_CLOCK_LAG


class LagLog:
    """Counts missed and late cycles per window and warns when they cross ``limits``.

    ``update(missed, late)`` takes the backend's running totals once per cycle: an increment and
    two integer comparisons while nothing changed. On a change, a jump of k missed cycles is a
    hold-up of about k + 1 periods (compared with ``limits.gap_s``); when a window has passed, its
    share of missed and late cycles is compared with ``limits.fraction``. A crossing logs one
    WARNING, with the likely cause (``LagCauses``), unless one was logged less than
    ``limits.interval_s`` ago: then it is counted in the next line.
    """

    __slots__ = (
        "_cycles",
        "_held",
        "_next",
        "_seen_late",
        "_seen_missed",
        "_window_cycles",
        "_window_late",
        "_window_missed",
        "_window_start",
        "causes",
        "clock",
        "limits",
        "logger",
        "period",
        "warnings",
        "what",
    )

    def __init__(
        self,
        what: str,
        logger: logging.Logger,
        *,
        period: float,
        limits: LagLimits = OWN_CLOCK_LAG,
        clock: Callable[[], float] = time.monotonic,
        causes: LagCauses | None = None,
    ) -> None:
        self.what = what
        self.logger = logger
        self.period = period
        self.limits = limits
        """When to speak; the ``ur`` backend sets ``ur_lag_limits`` of its program's timeout."""
        self.clock = clock
        """The time source (seconds); tests inject their own."""
        self.causes = LagCauses() if causes is None else causes
        """What names the likely cause (CPU steal, other processes, garbage collection)."""
        self.warnings = 0
        """WARNING lines logged so far."""
        self._cycles = 0
        self._seen_missed = 0
        self._seen_late = 0
        self._window_start: float | None = None
        self._window_cycles = 0
        self._window_missed = 0
        self._window_late = 0
        self._next = -math.inf
        self._held = 0
        """Crossings not logged (within ``interval_s`` of the last line)."""

    def update(self, missed: int, late: int) -> None:
        """Take the totals of missed and late cycles; log a warning if a limit was crossed."""
        self._cycles += 1
        if missed == self._seen_missed and late == self._seen_late:
            return
        jump = missed - self._seen_missed
        self._seen_missed, self._seen_late = missed, late
        now = self.clock()
        limits = self.limits
        start = self._window_start
        if start is None:  # the first lag starts the first window; the cycles before it were on time
            start = self._window_start = now
            self._window_cycles, self._window_missed, self._window_late = self._cycles - 1, missed, late
        gap = (jump + 1) * self.period if jump > 0 else 0.0
        if gap >= limits.gap_s:
            why = (
                f"a hold-up of {gap * 1e3:.0f} ms ({jump} cycles missed at once; "
                f"warns from {limits.gap_s * 1e3:.0f} ms)"
            )
            self._cross(now, why, missed, late, since=now - gap - self.period)
        if now - start < limits.window_s:
            return
        cycles = self._cycles - self._window_cycles
        lagged = (missed - self._window_missed) + (late - self._window_late)
        share = lagged / (cycles + missed - self._window_missed)
        self._window_start, self._window_cycles = now, self._cycles
        self._window_missed, self._window_late = missed, late
        if share > limits.fraction:
            why = (
                f"{share:.1%} of cycles missed or late over the last {now - start:.0f} s "
                f"(warns above {limits.fraction:.0%})"
            )
            self._cross(now, why, missed, late, since=start)

    def _cross(self, now: float, why: str, missed: int, late: int, since: float) -> None:
        """Log a crossing (rate-limited), naming the likely cause of the lag that began at ``since``."""
        if now < self._next:
            self._held += 1
            return
        held = f"; {self._held} more such since the last line" if self._held else ""
        self.logger.warning(
            "%s: %s%s (%d missed, %d late in all; cycle_stats, doctor): %s",
            self.what,
            why,
            held,
            missed,
            late,
            self.causes.describe(since),
        )
        self.warnings += 1
        self._held = 0
        self._next = now + self.limits.interval_s
