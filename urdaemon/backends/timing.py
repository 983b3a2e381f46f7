"""A fixed-bin histogram of durations, cheap enough to record one value per cycle at 500 Hz."""

from __future__ import annotations

__all__ = ["Histogram"]

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
