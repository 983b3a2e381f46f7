"""The rate statistics (introspect/rates.py), from tables and properties: times in, numbers out."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from urdaemon.introspect.rates import GAP_FACTOR, RateWindow, format_stats, rate_stats

MS = 1_000_000


@pytest.mark.parametrize(
    ("times", "rate", "low", "high", "gaps", "largest", "backwards"),
    [
        ([0, 2 * MS, 4 * MS, 6 * MS], 500.0, 0.002, 0.002, 0, None, 0),
        ([0, 8 * MS], 125.0, 0.008, 0.008, 0, None, 0),
        ([0, 2 * MS, 4 * MS, 10 * MS, 12 * MS], 1 / 0.003, 0.002, 0.006, 1, 0.006, 0),
        ([0, 2 * MS, 2 * MS, 4 * MS], 500.0, 0.002, 0.002, 0, None, 1),  # a time that stood still
        ([0, 2 * MS, 1 * MS, 3 * MS], 500.0, 0.002, 0.002, 0, None, 1),  # and one that went back
        ([0, 2 * MS, 4 * MS, 7 * MS], 1 / (7 / 3 / 1000), 0.002, 0.003, 0, None, 0),  # 1.5x: not a gap
        ([0, 2 * MS, 4 * MS, 7 * MS + 1], 1 / ((7 * MS + 1) / 3e9), 0.002, 0.003 + 1e-9, 1, 0.003 + 1e-9, 0),
    ],
)
def test_rate_stats_from_a_table(
    times: list[int], rate: float, low: float, high: float, gaps: int, largest: float | None, backwards: int
) -> None:
    stats = rate_stats(times)
    assert stats is not None
    assert stats.rate_hz == pytest.approx(rate)
    assert stats.min_s == pytest.approx(low)
    assert stats.max_s == pytest.approx(high)
    assert stats.gaps == gaps
    assert stats.largest_gap_s == (None if largest is None else pytest.approx(largest))
    assert stats.backwards == backwards


@pytest.mark.parametrize("times", [[], [5], [5, 5], [5, 4]])
def test_no_stats_without_two_increasing_times(times: list[int]) -> None:
    assert rate_stats(times) is None


def test_the_std_and_median_of_a_known_set() -> None:
    stats = rate_stats([0, 1 * MS, 4 * MS, 6 * MS])  # periods 1, 3, 2 ms
    assert stats is not None
    assert stats.median_s == pytest.approx(0.002)
    assert stats.std_s == pytest.approx(math.sqrt(2 / 3) / 1000)


@given(
    period_ns=st.integers(min_value=1_000, max_value=10**9),
    start=st.integers(min_value=0, max_value=2**62),
    n=st.integers(min_value=2, max_value=300),
)
def test_evenly_spaced_times_have_that_rate_and_no_spread(period_ns: int, start: int, n: int) -> None:
    stats = rate_stats([start + i * period_ns for i in range(n)])
    assert stats is not None
    assert stats.periods == n - 1
    assert stats.rate_hz == pytest.approx(1e9 / period_ns)
    assert stats.std_s == pytest.approx(0.0, abs=1e-12)
    assert stats.gaps == 0
    assert stats.largest_gap_s is None


@given(
    periods=st.lists(st.integers(min_value=1, max_value=10**8), min_size=1, max_size=200),
    missing=st.integers(min_value=2, max_value=50),
)
def test_a_missing_message_run_is_a_gap_and_the_order_holds(periods: list[int], missing: int) -> None:
    even = [periods[0]] * len(periods) * 3  # a steady stream, then a hole of ``missing`` periods
    times = [0]
    for p in even:
        times.append(times[-1] + p)
    times.append(times[-1] + missing * periods[0])
    stats = rate_stats(times)
    assert stats is not None
    assert stats.min_s <= stats.median_s <= stats.max_s
    assert stats.min_s <= stats.mean_s <= stats.max_s
    assert stats.gaps == 1
    assert stats.largest_gap_s == pytest.approx(missing * periods[0] / 1e9)
    assert stats.largest_gap_s is not None
    assert stats.largest_gap_s > GAP_FACTOR * stats.median_s


@given(st.lists(st.integers(min_value=0, max_value=10**12), min_size=0, max_size=200))
def test_any_times_give_consistent_stats_or_none(times: list[int]) -> None:
    stats = rate_stats(times)
    if stats is None:
        return
    assert stats.periods + stats.backwards == len(times) - 1
    assert stats.min_s <= stats.mean_s * (1 + 1e-9)
    assert stats.mean_s <= stats.max_s * (1 + 1e-9)
    assert stats.rate_hz == pytest.approx(1 / stats.mean_s)
    assert 0 <= stats.gaps < stats.periods or stats.periods == stats.gaps == 0


def test_the_window_keeps_the_newest_periods_and_counts_all() -> None:
    window = RateWindow(3)
    window.extend([0, 100 * MS, 101 * MS, 102 * MS, 103 * MS])  # the slow first period falls out
    assert window.count == 5
    stats = window.stats()
    assert stats is not None
    assert stats.periods == 3
    assert stats.rate_hz == pytest.approx(1000.0)
    with pytest.raises(ValueError, match="at least 1 period"):
        RateWindow(0)


def test_the_text_is_ros2_topic_hz_s_and_names_the_time_source() -> None:
    stats = rate_stats([0, 2 * MS, 4 * MS, 10 * MS])
    text = format_stats(stats, source="host_time_ns")
    lines = text.splitlines()
    assert lines[0] == "average rate: 300.000"
    assert lines[1] == "\tmin: 0.002000s max: 0.006000s std dev: 0.001886s window: 4"
    assert (
        lines[2] == "\t1 gap(s) over 1.5x the median 0.002000s, the largest 0.006000s (times: host_time_ns)"
    )
    assert format_stats(None, source="receive time") == "no rate yet: fewer than two messages"
