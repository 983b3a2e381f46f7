"""How often messages arrive: the rate, the spread of the period and the gaps, as ``ros2 topic hz``
shows them. Pure: the times are given (ns), nothing here reads a clock.

The period between two messages is the difference of their times: the messages' own
``host_time_ns`` (when the daemon had the state: what the robot's cycle did) where they carry it,
else when they were received (what the network and this process added too). A period longer than
``GAP_FACTOR`` times the median is a gap: a message that never came, or came late.
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

__all__ = ["DEFAULT_WINDOW", "GAP_FACTOR", "RateStats", "RateWindow", "format_stats", "rate_stats"]

GAP_FACTOR = 1.5
"""A period over this many times the median is a gap."""
DEFAULT_WINDOW = 10_000
"""Periods the statistics are taken over (the newest), as ``ros2 topic hz`` keeps."""


@dataclass(frozen=True, slots=True)
class RateStats:
    """The statistics of the periods between successive messages (s)."""

    periods: int
    """Periods measured: one fewer than the messages in the window."""
    rate_hz: float
    """Messages per second: 1 / the mean period."""
    mean_s: float
    min_s: float
    max_s: float
    std_s: float
    """Population standard deviation of the period."""
    median_s: float
    gaps: int
    """Periods over ``GAP_FACTOR`` times the median."""
    largest_gap_s: float | None
    """The longest of those (None: no gap)."""
    backwards: int
    """Times that went back (or stood still) from the message before: left out of the periods."""


def rate_stats(times_ns: Sequence[int], *, gap_factor: float = GAP_FACTOR) -> RateStats | None:
    """The statistics of the periods between ``times_ns`` (in the order the messages came); None
    while there are fewer than two increasing times (nothing to measure yet)."""
    periods: list[float] = []
    backwards = 0
    for earlier, later in itertools.pairwise(times_ns):
        if later <= earlier:
            backwards += 1
        else:
            periods.append((later - earlier) / 1e9)
    if not periods:
        return None
    n = len(periods)
    mean = math.fsum(periods) / n
    variance = math.fsum((p - mean) ** 2 for p in periods) / n
    ordered = sorted(periods)
    median = ordered[n // 2] if n % 2 else (ordered[n // 2 - 1] + ordered[n // 2]) / 2
    gaps = [p for p in periods if p > gap_factor * median]
    return RateStats(
        periods=n,
        rate_hz=1.0 / mean,
        mean_s=mean,
        min_s=ordered[0],
        max_s=ordered[-1],
        std_s=math.sqrt(variance),
        median_s=median,
        gaps=len(gaps),
        largest_gap_s=max(gaps) if gaps else None,
        backwards=backwards,
    )


class RateWindow:
    """The newest ``window`` periods' times of one key, and how many messages came in all."""

    def __init__(self, window: int = DEFAULT_WINDOW) -> None:
        if window < 1:
            raise ValueError(f"the window must hold at least 1 period, got {window}")
        self._times: deque[int] = deque(maxlen=window + 1)
        self.count = 0
        """Messages added since the start."""

    def add(self, time_ns: int) -> None:
        """One message, at ``time_ns``."""
        self._times.append(time_ns)
        self.count += 1

    def extend(self, times_ns: Iterable[int]) -> None:
        """Several messages, in the order they came."""
        for time_ns in times_ns:
            self.add(time_ns)

    def stats(self, *, gap_factor: float = GAP_FACTOR) -> RateStats | None:
        """The statistics of the window (None: fewer than two messages yet)."""
        return rate_stats(list(self._times), gap_factor=gap_factor)


def format_stats(stats: RateStats | None, *, source: str) -> str:
    """``ros2 topic hz``'s lines for ``stats``, and the gaps and the time source on a line of their
    own (``source``: ``host_time_ns`` or ``receive time``)."""
    if stats is None:
        return "no rate yet: fewer than two messages"
    lines = [
        f"average rate: {stats.rate_hz:.3f}",
        f"\tmin: {stats.min_s:.6f}s max: {stats.max_s:.6f}s std dev: {stats.std_s:.6f}s "
        f"window: {stats.periods + 1}",
    ]
    gaps = (
        "no gaps"
        if stats.largest_gap_s is None
        else (
            f"{stats.gaps} gap(s) over {GAP_FACTOR:g}x the median {stats.median_s:.6f}s, "
            f"the largest {stats.largest_gap_s:.6f}s"
        )
    )
    extra = f"; {stats.backwards} time(s) went back" if stats.backwards else ""
    lines.append(f"\t{gaps}{extra} (times: {source})")
    return "\n".join(lines)
