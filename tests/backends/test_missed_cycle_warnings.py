"""Missed and late cycles are always counted, and warned of only when they cross the backend's limits
(``timing.LagLimits``): rate-limited, with counts and the likely cause.

Counted, never timed: the backend's clock is replaced by a stand-in whose counts of missed and late
cycles the test sets, and the warning's time source by a variable the test advances.
"""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from urdaemon.backends import MockBackend
from urdaemon.backends.lag_causes import GcWatch, LagCauses
from urdaemon.backends.servo import ServoBackend
from urdaemon.backends.timing import OWN_CLOCK_LAG, UR_LAG, LagLog, lag_limits, ur_lag_limits
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


def _rig(backend: MockBackend, tmp_path: Path) -> tuple[FakeClock, Now]:
    clock = FakeClock()
    backend._clock = clock  # type: ignore[assignment]
    now = Now()
    backend.lag_log.clock = now
    backend.lag_log.causes = LagCauses(proc_stat=tmp_path / "no-stat", watch=GcWatch())
    return clock, now


def test_each_backend_kind_has_its_limits() -> None:
    assert lag_limits("ur") is UR_LAG
    assert lag_limits("mock") is lag_limits("servo") is OWN_CLOCK_LAG
    assert UR_LAG.fraction == 0.01
    assert UR_LAG.gap_s == 0.1  # half of the program's default hold: 100 cycles at 500 Hz
    assert OWN_CLOCK_LAG.fraction >= 10 * UR_LAG.fraction
    assert OWN_CLOCK_LAG.gap_s >= 5 * UR_LAG.gap_s
    assert ur_lag_limits(0.4).gap_s == 0.2


def test_the_mock_counts_small_misses_silently_and_warns_of_a_long_hold_up_once_per_interval(
    caplog: pytest.LogCaptureFixture, tmp_path: Path
) -> None:
    """Reproduction (issue 32): the mock demo logged a WARNING every 5 s per robot at load ~1, the
    first at start-up. Misses that lose nothing are counted only; a half-second stall warns once,
    a second one within the interval is held for the next line."""
    caplog.set_level(logging.WARNING)
    backend = MockBackend("alice", JOINTS, 500.0)
    clock, now = _rig(backend, tmp_path)
    backend.step()
    clock.missed, clock.late = 10, 3  # a 22 ms hold-up at start-up: counted only
    backend.step()
    for _ in range(100):
        now.t += 0.002
        backend.step()
    assert _lag_lines(caplog) == []
    assert backend.statistics().missed_cycles == 10
    assert backend.statistics().late_cycles == 3

    clock.missed += 300  # a 0.6 s stall
    clock.late += 1
    backend.step()
    lines = _lag_lines(caplog)
    assert len(lines) == 1
    assert "robot 'alice' (mock backend): a hold-up of 602 ms (300 cycles missed at once" in lines[0]
    assert "(310 missed, 4 late in all" in lines[0]
    assert "garbage collection" in lines[0]  # no cause known here: says what it looked for

    now.t += 1.0
    clock.missed += 300  # again within the interval: held, said in the next line
    backend.step()
    assert len(_lag_lines(caplog)) == 1
    now.t += OWN_CLOCK_LAG.interval_s
    clock.missed += 300
    backend.step()
    lines = _lag_lines(caplog)
    assert len(lines) == 2
    assert "1 more such since the last line" in lines[1]
    assert backend.lag_log.warnings == 2


def test_a_sustained_rate_above_the_limit_warns(caplog: pytest.LogCaptureFixture, tmp_path: Path) -> None:
    """A third of the mock's cycles missed for 30 s (above its 25 %) warns once; the line says so."""
    caplog.set_level(logging.WARNING)
    backend = MockBackend("bob", JOINTS, 100.0)
    clock, now = _rig(backend, tmp_path)
    for k in range(1, 2 * 1600 + 1):  # 32 s of 100 Hz slots, every other cycle followed by a miss
        if k % 2 == 0:
            clock.missed += 1
        now.t += 0.01
        backend.step()
    lines = _lag_lines(caplog)
    assert len(lines) == 1, lines
    assert "33.3% of cycles missed or late over the last 30 s (warns above 25%)" in lines[0]


def test_the_servo_backend_uses_the_same_limits(caplog: pytest.LogCaptureFixture, tmp_path: Path) -> None:
    caplog.set_level(logging.WARNING)
    options = ServoOptions.model_validate(
        {"rate_hz": 50.0, "joints": [{"name": "j1", "channel": 0}, {"name": "j2", "channel": 1}]}
    )
    backend = ServoBackend("arm", ("arm_j1", "arm_j2"), "arm_", options)
    clock, _now = _rig(backend, tmp_path)
    clock.missed = 4  # 100 ms: nothing physical lost
    backend.step()
    assert _lag_lines(caplog) == []
    clock.missed = 40  # 0.74 s
    backend.step()
    (line,) = _lag_lines(caplog)
    assert "robot 'arm' (servo backend): a hold-up of 740 ms (36 cycles missed at once" in line


def test_ur_limits_warn_of_a_gap_approaching_the_receive_timeout(caplog: pytest.LogCaptureFixture) -> None:
    """With a 0.1 s hold (``ur_lag_limits(0.1)``), at 500 Hz a 30 ms gap is counted; a 60 ms one
    (past half of it) warns."""
    caplog.set_level(logging.WARNING)
    now = Now()
    lag = LagLog(
        "robot 'x' (ur backend)",
        logging.getLogger("test.lag"),
        period=0.002,
        limits=ur_lag_limits(0.1),
        clock=now,
        causes=LagCauses(proc_stat=Path("/nonexistent"), watch=GcWatch()),
    )
    lag.update(14, 1)
    assert _lag_lines(caplog) == []
    lag.update(43, 2)
    (line,) = _lag_lines(caplog)
    assert "a hold-up of 60 ms (29 cycles missed at once; warns from 50 ms)" in line


def test_lag_log_flood_is_bounded_by_the_interval(caplog: pytest.LogCaptureFixture) -> None:
    """A 1 s hold-up every 2 s for 10 minutes of (injected) time: one line per interval, no more."""
    caplog.set_level(logging.WARNING)
    now = Now()
    lag = LagLog(
        "robot 'x' (mock backend)",
        logging.getLogger("test.lag"),
        period=0.01,
        clock=now,
        causes=LagCauses(proc_stat=Path("/nonexistent"), watch=GcWatch()),
    )
    missed = 0
    for k in range(60_000):
        now.t += 0.01
        if k % 200 == 0:
            missed += 100
        lag.update(missed, 0)
    assert len(_lag_lines(caplog)) == 2  # t = 0 and 300 s of the 600 s


def test_the_cause_is_named_from_proc_stat_and_the_collections(tmp_path: Path) -> None:
    """CPU steal and other processes from /proc/stat's counters; a long collection from gc.callbacks."""
    stat = tmp_path / "stat"
    stat.write_text("cpu  100 0 100 800 0 0 0 0 0 0\n")
    own = [0.0]
    clock = [100.0]
    watch = GcWatch(clock=lambda: clock[0])
    causes = LagCauses(proc_stat=stat, own_cpu_s=lambda: own[0], watch=watch)
    # 1000 ticks later: 700 busy (100 of them this process at 100 ticks/s... whatever the tick rate,
    # it is small here), 100 idle, 200 stolen
    stat.write_text("cpu  800 0 100 900 0 0 0 200 0 0\n")
    watch.long.append((150.0, 0.04))  # a 40 ms collection that ended at t = 150 s
    text = causes.describe(since=149.0)
    assert "CPU steal 20%" in text
    assert "other processes kept the CPUs 70% busy" in text
    assert "a garbage collection took 40 ms" in text
    assert "likely cause" in causes.describe(since=149.0) or "no CPU steal" in causes.describe(since=149.0)


def test_a_collection_before_the_lag_is_not_its_cause(tmp_path: Path) -> None:
    """The start-up collection (it freezes the start-up objects, before any cycle) is no cause of a lag
    minutes later: only a collection that ended within the lag is named."""
    clock = [0.0]
    watch = GcWatch(clock=lambda: clock[0])
    watch.long.append((1.0, 0.837))  # start-up, at t = 1 s
    causes = LagCauses(proc_stat=tmp_path / "no-stat", watch=watch)
    assert "garbage collection took" not in causes.describe(since=300.0)
    watch.long.append((300.2, 0.05))
    assert "a garbage collection took 50 ms" in causes.describe(since=300.0)
    assert "a garbage collection took 837 ms" in causes.describe(since=0.5), "the longest since then"


def test_the_watch_keeps_only_long_collections(tmp_path: Path) -> None:
    """Each collection costs a clock read; only those of GC_PAUSE_S or more are kept, with their end."""
    clock = [5.0]
    watch = GcWatch(clock=lambda: clock[0])
    for _ in range(100):
        watch._on_gc("start", {})
        watch._on_gc("stop", {})  # microseconds: not kept
    assert list(watch.long) == []
    assert watch.longest_since(0.0) == 0.0
