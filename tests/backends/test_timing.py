"""The cycle-time histogram: percentiles to the microsecond, exact maximum, reset."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from urdaemon.backends.timing import BINS, Histogram


def test_empty_histogram_reports_zeros() -> None:
    assert Histogram().summary() == {"count": 0, "p50_us": 0.0, "p99_us": 0.0, "p999_us": 0.0, "max_us": 0.0}


def test_percentiles_of_a_known_distribution() -> None:
    h = Histogram()
    for us in range(1, 1001):  # 1 µs … 1000 µs, one each, recorded as x.5 µs
        h.record(us * 1_000 - 500)
    summary = h.summary()
    assert summary["count"] == 1000
    assert summary["p50_us"] == 500.0
    assert summary["p99_us"] == 990.0
    assert summary["p999_us"] == 999.0
    assert summary["max_us"] == 999.5  # exact, not a bin edge


def test_values_beyond_the_last_bin_and_negative_ones_are_kept() -> None:
    h = Histogram()
    h.record(-5)  # a clock that stepped back: counted in the first bin
    h.record(BINS * 1_000 * 3)
    assert h.count == 2
    assert h.percentile_us(1.0) == BINS * 3.0  # the last bin's edge is capped by the exact max
    assert h.percentile_us(0.5) == 1.0  # the first bin: [0, 1 µs)
    h.reset()
    assert (h.count, h.max_ns, h.percentile_us(0.5)) == (0, 0, 0.0)


def test_fraction_out_of_range_is_refused() -> None:
    with pytest.raises(ValueError, match="fraction"):
        Histogram().percentile_us(1.5)


@settings(max_examples=100, deadline=None)
@given(values=st.lists(st.integers(min_value=0, max_value=5_000_000), min_size=1, max_size=300))
def test_percentile_is_within_one_bin_of_the_exact_quantile(values: list[int]) -> None:
    h = Histogram()
    for v in values:
        h.record(v)
    ordered = sorted(values)
    for fraction in (0.5, 0.99, 0.999, 1.0):
        rank = max(1, -(-len(values) * fraction // 1))
        exact_us = ordered[int(rank) - 1] / 1_000.0
        got = h.percentile_us(fraction)
        assert exact_us <= got <= exact_us + 1.0
    assert h.max_ns == max(values)
