"""Missed and late cycles of the mock and servo backends are logged: rate-limited, with counts.

Counted, never timed: the backend's clock is replaced by a stand-in whose counts of missed and late
cycles the test sets, and the warning's time source by a variable the test advances.
"""

from __future__ import annotations

import logging

import pytest

from urdaemon.backends import MockBackend
from urdaemon.backends.servo import ServoBackend
from urdaemon.backends.timing import LAG_LOG_INTERVAL_S, LagLog
from urdaemon.cell.servo import ServoOptions

JOINTS = ("a_j1", "a_j2")


class FakeClock:
    """What ``step()`` reads from the backend's periodic clock, set by the test."""

    def __init__(self) -> None:
        self.missed = 0
        self.late = 0
        self.max_lateness = 0.0


class Now:
    """A time source the test advances."""

    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def _lag_lines(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [
        r.getMessage() for r in caplog.records if r.levelno == logging.WARNING and "missed" in r.getMessage()
    ]


def _rig(backend: MockBackend) -> tuple[FakeClock, Now]:
    clock = FakeClock()
    backend._clock = clock  # type: ignore[assignment]
    now = Now()
    backend.lag_log.clock = now
    return clock, now


def test_the_mock_warns_of_missed_cycles_at_most_once_per_interval_with_counts(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Reproduction: a mock on a busy machine skipped 8-13 % of its cycles and nothing was logged.

    Here its clock reports 10 missed cycles and 3 late ones, then more within the interval (no new
    line), then the interval passes (one line with the cycles since the last line and the totals)."""
    caplog.set_level(logging.WARNING)
    backend = MockBackend("alice", JOINTS, 500.0)
    clock, now = _rig(backend)
    for _ in range(100):  # healthy cycles: nothing to say
        backend.step()
        now.t += 0.002
    assert _lag_lines(caplog) == []

    clock.missed, clock.late = 10, 3
    backend.step()
    lines = _lag_lines(caplog)
    assert len(lines) == 1
    assert "robot 'alice' (mock backend)" in lines[0]
    assert "10 cycles missed and 3 late" in lines[0]
    assert "(10 missed, 3 late in all)" in lines[0]

    # More misses within the interval: counted, not logged yet.
    for k in range(1, 1001):
        if k % 100 == 0:
            clock.missed += 2
            clock.late += 1
        now.t += LAG_LOG_INTERVAL_S / 2000
        backend.step()
    assert len(_lag_lines(caplog)) == 1

    # The interval passes: the next cycle says what was counted since the last line, even with no new miss.
    now.t += LAG_LOG_INTERVAL_S / 2
    backend.step()
    lines = _lag_lines(caplog)
    assert len(lines) == 2
    assert "20 cycles missed and 10 late in the last 5 s" in lines[1]
    assert "(30 missed, 13 late in all)" in lines[1]
    assert backend.statistics().missed_cycles == 30

    # Nothing new: silence, however long it lasts.
    for _ in range(10):
        now.t += LAG_LOG_INTERVAL_S
        backend.step()
    assert len(_lag_lines(caplog)) == 2


def test_the_servo_backend_warns_too(caplog: pytest.LogCaptureFixture) -> None:
    """Reproduction: the servo backend (a mock underneath) missed cycles silently as well."""
    caplog.set_level(logging.WARNING)
    options = ServoOptions.model_validate(
        {
            "rate_hz": 50.0,
            "joints": [
                {"name": "j1", "channel": 0},
                {"name": "j2", "channel": 1},
            ],
        }
    )
    backend = ServoBackend("arm", ("arm_j1", "arm_j2"), "arm_", options)
    clock, _now = _rig(backend)
    clock.missed = 4
    backend.step()
    (line,) = _lag_lines(caplog)
    assert "robot 'arm' (servo backend): 4 cycles missed and 0 late" in line


def test_lag_log_flood_is_bounded_by_the_interval(caplog: pytest.LogCaptureFixture) -> None:
    """A miss every cycle for 58 s of (injected) time gives one line per interval, no more."""
    caplog.set_level(logging.WARNING)
    now = Now()
    lag = LagLog("robot 'x' (mock backend)", logging.getLogger("test.lag"), interval_s=5.0, clock=now)
    for k in range(1, 29_001):
        now.t += 0.002
        lag.update(k, 0)
    lines = _lag_lines(caplog)
    assert len(lines) == 12  # t = 0 s, 5 s, ..., 55 s of the 60 s
    assert "(29000 missed" not in lines[-1]  # the last 3 s are still pending
