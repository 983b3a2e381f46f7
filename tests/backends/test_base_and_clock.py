"""``Backend.check_io``, the base class defaults, and ``PeriodicClock`` on a fake clock (no real sleeping)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import pytest

from urdaemon.backends import Backend, BackendStatistics
from urdaemon.backends.base import IO_KINDS
from urdaemon.backends.clock import PeriodicClock
from urdaemon.errors import BackendError
from urdaemon.model import CommandMode

SIZES = {"digital": 8, "configurable": 8, "tool": 2, "analog": 2}


# --- check_io ---


@pytest.mark.parametrize(
    ("kind", "pin", "value"),
    [
        ("digital", 0, True),
        ("digital", 7, False),
        ("configurable", 7, True),
        ("tool", 0, False),
        ("tool", 1, True),
        ("analog", 0, 0.0),
        ("analog", 1, 1.0),
        ("analog", 1, 0.5),
        ("analog", 0, 1),
    ],
)
def test_check_io_accepts_good_requests(kind: str, pin: int, value: float | bool) -> None:
    assert Backend.check_io(kind, pin, value, SIZES) is None


@pytest.mark.parametrize(
    ("kind", "pin", "value", "message"),
    [
        (
            "Digital",
            0,
            True,
            "unknown IO kind 'Digital'; expected one of digital, configurable, tool, analog",
        ),
        ("", 0, True, "unknown IO kind ''"),
        ("digital", 8, True, "digital output pin 8 out of range 0..7"),
        ("digital", -1, True, "digital output pin -1 out of range 0..7"),
        ("tool", 2, False, "tool output pin 2 out of range 0..1"),
        ("analog", 5, 0.5, "analog output pin 5 out of range 0..1"),
        ("analog", 0, 1.0000001, "analog output value must be a number in 0..1, got 1.0000001"),
        ("analog", 0, -1e-9, "analog output value must be a number in 0..1, got -1e-09"),
        ("analog", 0, math.inf, "analog output value must be a number in 0..1, got inf"),
        ("analog", 0, math.nan, "analog output value must be a number in 0..1, got nan"),
        ("analog", 0, False, "analog output value must be a number in 0..1, got False"),
        ("digital", 0, 1.0, "digital output value must be true or false, got 1.0"),
        ("configurable", 0, 0, "configurable output value must be true or false, got 0"),
    ],
)
def test_check_io_names_the_problem(kind: str, pin: int, value: float | bool, message: str) -> None:
    with pytest.raises(BackendError) as info:
        Backend.check_io(kind, pin, value, SIZES)
    assert str(info.value).startswith(message)


def test_check_io_uses_the_given_sizes() -> None:
    Backend.check_io("digital", 15, True, {"digital": 16})
    with pytest.raises(BackendError, match="unknown IO kind 'tool'; expected one of digital"):
        Backend.check_io("tool", 0, True, {"digital": 16})
    with pytest.raises(BackendError, match="out of range"):
        Backend.check_io("digital", 0, True, {"digital": 0})


def test_io_kinds() -> None:
    assert IO_KINDS == ("digital", "configurable", "tool", "analog")
    assert set(IO_KINDS) == set(SIZES)


# --- the base class ---


class Bare(Backend):
    kind = "bare"

    async def run(self, on_cycle: Callable[[], None]) -> None:
        on_cycle()


async def test_base_backend_defaults() -> None:
    backend = Bare("x", ("x_a", "x_b"), 125.0)
    assert backend.period == 1.0 / 125.0
    assert backend.state.joint_names == ("x_a", "x_b")
    assert backend.state.positions == [0.0, 0.0]
    assert backend.command.mode is CommandMode.IDLE
    assert backend.command.positions == [0.0, 0.0]
    assert backend.statistics() == BackendStatistics(0, 0, 0, 0.0, 0)
    with pytest.raises(BackendError, match="bare backend has no IO"):
        await backend.set_io("digital", 0, True)
    with pytest.raises(BackendError, match="bare backend has no payload"):
        await backend.set_payload(1.0, (0.0, 0.0, 0.0))
    with pytest.raises(BackendError, match="bare backend has no speed slider"):
        await backend.set_speed_slider(0.5)
    calls: list[int] = []
    await backend.run(lambda: calls.append(1))
    assert calls == [1]


def test_backend_is_abstract() -> None:
    with pytest.raises(TypeError):
        Backend("x", ("a",), 100.0)  # type: ignore[abstract]


def test_statistics_are_frozen() -> None:
    stats = BackendStatistics(1, 2, 3, 0.5, 4)
    with pytest.raises(dataclasses.FrozenInstanceError):
        stats.cycles = 5  # type: ignore[misc]


# --- PeriodicClock on a fake clock ---


class FakeTime:
    """The clock's time source (``now=``): advanced only by the fake sleep and the test."""

    def __init__(self, now: float) -> None:
        self.now = now

    def monotonic(self) -> float:
        return self.now


class FakeAsyncio:
    """The clock's wait (``sleep=``): advances the fake time at once."""

    def __init__(self, time: FakeTime) -> None:
        self.time = time
        self.delays: list[float] = []
        self.overshoot = 0.0
        """Extra seconds every sleep takes (a busy loop wakes late)."""

    async def sleep(self, delay: float) -> None:
        self.delays.append(delay)
        self.time.now += delay + self.overshoot


@pytest.fixture
def fake() -> tuple[FakeTime, FakeAsyncio]:
    time = FakeTime(100.0)
    aio = FakeAsyncio(time)
    return time, aio


# Periods and times are binary fractions so the arithmetic is exact.
PERIOD = 0.25


async def test_clock_wakes_on_the_grid(fake: tuple[FakeTime, FakeAsyncio]) -> None:
    time, aio = fake
    clock = PeriodicClock(PERIOD, now=time.monotonic, sleep=aio.sleep)
    clock.start()
    for k in range(1, 9):
        await clock.wait()
        assert time.now == 100.0 + k * PERIOD
    assert aio.delays == [PERIOD] * 8
    assert (clock.missed, clock.late, clock.max_lateness) == (0, 0, 0.0)


async def test_clock_does_not_drift_when_work_takes_time(fake: tuple[FakeTime, FakeAsyncio]) -> None:
    time, aio = fake
    clock = PeriodicClock(PERIOD, now=time.monotonic, sleep=aio.sleep)
    clock.start()
    for k in range(1, 6):
        time.now += 0.125  # the cycle's work takes half a period
        await clock.wait()
        assert time.now == 100.0 + k * PERIOD
    assert aio.delays == [0.125] * 5
    assert clock.missed == 0


async def test_clock_compensates_late_wake_ups(fake: tuple[FakeTime, FakeAsyncio]) -> None:
    time, aio = fake
    aio.overshoot = 0.0625
    clock = PeriodicClock(PERIOD, now=time.monotonic, sleep=aio.sleep)
    clock.start()
    for k in range(1, 6):
        await clock.wait()
        assert time.now == 100.0 + k * PERIOD + 0.0625
    assert aio.delays == [PERIOD] + [PERIOD - 0.0625] * 4
    assert clock.max_lateness == 0.0625
    assert clock.late == 0  # below the default threshold of one period


async def test_clock_counts_late_cycles_over_the_threshold(fake: tuple[FakeTime, FakeAsyncio]) -> None:
    time, aio = fake
    aio.overshoot = 0.0625
    clock = PeriodicClock(PERIOD, late_threshold=0.03125, now=time.monotonic, sleep=aio.sleep)
    assert clock.late_threshold == 0.03125
    clock.start()
    for _ in range(3):
        await clock.wait()
    assert clock.late == 3
    assert clock.max_lateness == 0.0625


async def test_clock_skips_grid_points_that_passed_by_a_whole_cycle(
    fake: tuple[FakeTime, FakeAsyncio],
) -> None:
    time, aio = fake
    clock = PeriodicClock(PERIOD, now=time.monotonic, sleep=aio.sleep)
    clock.start()
    time.now += 3.5 * PERIOD  # a stall: grid points 1, 2 and 3 passed
    await clock.wait()
    # points 1 and 2 passed by a whole period and are skipped; point 3 runs at once, half a period late
    assert clock.missed == 2
    assert aio.delays == [0.0]
    assert time.now == 100.0 + 3.5 * PERIOD
    assert clock.max_lateness == 0.5 * PERIOD
    await clock.wait()
    assert time.now == 100.0 + 4 * PERIOD  # back on the grid
    assert aio.delays[-1] == 0.5 * PERIOD
    assert clock.missed == 2


async def test_clock_late_by_less_than_a_period_skips_nothing(fake: tuple[FakeTime, FakeAsyncio]) -> None:
    time, aio = fake
    clock = PeriodicClock(PERIOD, now=time.monotonic, sleep=aio.sleep)
    clock.start()
    time.now += 1.75 * PERIOD  # point 1 passed by three quarters of a period
    await clock.wait()
    assert clock.missed == 0
    assert aio.delays == [0.0]
    assert clock.max_lateness == 0.75 * PERIOD
    await clock.wait()
    assert time.now == 100.0 + 2 * PERIOD


async def test_clock_never_sleeps_a_negative_delay(fake: tuple[FakeTime, FakeAsyncio]) -> None:
    time, aio = fake
    clock = PeriodicClock(PERIOD, now=time.monotonic, sleep=aio.sleep)
    clock.start()
    for stall in (0.3, 1.1, 0.0, 2.6, 0.26):
        time.now += stall
        await clock.wait()
    assert all(d >= 0.0 for d in aio.delays)
    assert len(aio.delays) == 5


@pytest.mark.parametrize("kind", ["thread", "timerfd"])
async def test_tick_clocks_tick_on_the_loop_and_stop(kind: str) -> None:
    import asyncio
    import os
    import threading

    from urdaemon.backends.clock import ThreadClock, TimerFdClock, tick_clock

    loop = asyncio.get_running_loop()
    ten = asyncio.Event()
    ticks: list[int] = []

    def tick() -> None:
        ticks.append(threading.get_ident())
        if len(ticks) == 10:
            ten.set()

    if kind == "thread":
        clock: ThreadClock | TimerFdClock = ThreadClock(0.002, tick, loop)
    else:
        made = tick_clock(0.002, tick, loop)
        assert isinstance(made, TimerFdClock)  # Linux: the loop wakes on a timerfd
        clock = made
    threads_before = threading.active_count()
    clock.start()
    assert threading.active_count() == threads_before + (kind == "thread"), "a thread only for 'thread'"
    timer_fd = clock._fd if isinstance(clock, TimerFdClock) else -1
    await asyncio.wait_for(ten.wait(), 5.0)
    clock.stop()
    seen = len(ticks)
    for _ in range(3):  # let any tick already handed to the loop run
        await asyncio.sleep(0)
    assert set(ticks) == {threading.get_ident()}, "ticks run on the loop's thread"
    # the thread may have handed one tick over just before stop; the timerfd is gone at once
    assert len(ticks) <= seen + (kind == "thread"), "no ticks after stop"
    if timer_fd >= 0:
        with pytest.raises(OSError, match="Bad file descriptor"):  # the timer's fd is closed
            os.fstat(timer_fd)
    clock.stop()  # twice is harmless


@pytest.mark.parametrize(("catch_up", "burst"), [(1, 1), (4, 4)])
async def test_timerfd_clock_after_a_stall_ticks_catch_up_times_and_counts_the_rest_missed(
    catch_up: int, burst: int
) -> None:
    import asyncio
    import time

    from urdaemon.backends.clock import TimerFdClock

    loop = asyncio.get_running_loop()
    first = asyncio.Event()
    ticks: list[float] = []

    def tick() -> None:
        ticks.append(time.monotonic())
        first.set()

    clock = TimerFdClock(0.002, tick, loop, catch_up=catch_up)
    wakeups: list[int] = []  # ticks run by each wake-up (a busy machine may add a wake-up before we look)
    expired = clock._expired

    def counted() -> None:
        before = len(ticks)
        expired()
        wakeups.append(len(ticks) - before)

    clock._expired = counted  # type: ignore[method-assign]
    clock.start()
    try:
        time.sleep(0.021)  # noqa: ASYNC251 (the stimulus: the loop is held up for over ten periods)
        await asyncio.wait_for(first.wait(), 5.0)
        # the first wake-up that found expirations (over ten of them) ran catch_up ticks, no more
        assert next(n for n in wakeups if n) == burst
        assert clock.missed >= 10 - burst
    finally:
        clock.stop()


def test_clocks_refuse_nonsense_settings() -> None:
    import asyncio

    from urdaemon.backends.clock import ThreadClock, TimerFdClock

    loop = asyncio.new_event_loop()
    try:
        with pytest.raises(ValueError, match="catch_up"):
            ThreadClock(0.002, lambda: None, loop, catch_up=0)
        with pytest.raises(ValueError, match="catch_up"):
            TimerFdClock(0.002, lambda: None, loop, catch_up=0)
        with pytest.raises(ValueError, match="period"):
            TimerFdClock(0.0, lambda: None, loop)
        with pytest.raises(ValueError, match="period"):
            ThreadClock(-0.002, lambda: None, loop)
    finally:
        loop.close()
