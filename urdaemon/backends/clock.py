"""A drift-free periodic clock for backends that have no robot to clock them (mock, servo)."""

from __future__ import annotations

import asyncio
import ctypes
import os
import sys
import threading
import time
from collections.abc import Awaitable, Callable
from typing import Protocol

__all__ = ["PeriodicClock", "ThreadClock", "TickClock", "TimerFdClock", "tick_clock"]


class PeriodicClock:
    """Wakes on an absolute grid of ``period`` seconds; counts late and skipped cycles.

    ``now`` and ``sleep`` are the time source and the wait (tests pass a simulated, loaded clock)."""

    def __init__(
        self,
        period: float,
        *,
        late_threshold: float | None = None,
        now: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], Awaitable[None]] = asyncio.sleep,
    ) -> None:
        self.period = period
        self.late_threshold = period if late_threshold is None else late_threshold
        self._now = now
        self._sleep = sleep
        self._next = 0.0
        self.missed = 0
        self.late = 0
        self.max_lateness = 0.0

    def start(self) -> None:
        """Start the grid at the current time."""
        self._next = self._now()

    async def wait(self) -> None:
        """Sleep until the next grid point; skip grid points that already passed by a whole cycle."""
        self._next += self.period
        now = self._now()
        if now - self._next > self.period:
            skipped = int((now - self._next) / self.period)
            self.missed += skipped
            self._next += skipped * self.period
        delay = self._next - now
        await self._sleep(delay if delay > 0.0 else 0.0)
        lateness = self._now() - self._next
        if lateness > self.max_lateness:
            self.max_lateness = lateness
        if lateness > self.late_threshold:
            self.late += 1


class _Ticker:
    """What both tick clocks keep: the period, the catch-up allowance, the count of missed ticks."""

    def __init__(
        self,
        period: float,
        tick: Callable[[], None],
        loop: asyncio.AbstractEventLoop,
        *,
        catch_up: int = 1,
    ) -> None:
        if not period > 0.0:
            raise ValueError(f"period must be positive, got {period}")
        if catch_up < 1:
            raise ValueError(f"catch_up must be at least 1, got {catch_up}")
        self.period = period
        self.catch_up = catch_up
        self.missed = 0
        self._tick = tick
        self._loop = loop


class ThreadClock(_Ticker):
    """Calls ``tick()`` on the event loop every ``period`` seconds, timed by a thread.

    asyncio rounds timer waits up to whole milliseconds (epoll), so a 2 ms grid slips and then
    catches up in pairs; a thread sleeping to absolute deadlines (``time.sleep``, ~0.1 ms precise)
    hands evenly spaced ticks to the loop instead, at a few per cent of a core. When the thread is
    late by more than ``catch_up`` periods (the process was stopped or starved), it skips to the
    present and counts the skipped ticks as ``missed`` instead of bursting; within that, late
    ticks are handed over back to back.
    """

    _thread: threading.Thread | None = None

    def start(self) -> None:
        """Start ticking."""
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="urdaemon-clock", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop ticking (returns once the thread has ended)."""
        if self._thread is None:
            return
        self._stop.set()
        self._thread.join(timeout=1.0)
        self._thread = None

    def _run(self) -> None:
        deadline = time.monotonic()
        while not self._stop.is_set():
            deadline += self.period
            now = time.monotonic()
            if now - deadline > self.catch_up * self.period:  # stopped or starved: skip, do not burst
                skipped = int((now - deadline) / self.period)
                self.missed += skipped
                deadline += skipped * self.period
            delay = deadline - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            try:
                self._loop.call_soon_threadsafe(self._tick)
            except RuntimeError:  # the loop closed
                return


class TickClock(Protocol):
    """What ``tick_clock`` returns: ticks ``tick()`` on the loop every ``period`` seconds."""

    period: float
    missed: int

    def start(self) -> None:
        """Start ticking."""

    def stop(self) -> None:
        """Stop ticking; no tick runs after this returns."""


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


class _Itimerspec(ctypes.Structure):
    _fields_ = [("it_interval", _Timespec), ("it_value", _Timespec)]


_CLOCK_MONOTONIC = 1  # <linux/time.h>


def _load_timerfd() -> tuple[Callable[..., int], Callable[..., int]] | None:
    """libc's ``timerfd_create`` and ``timerfd_settime`` (Linux), or None where there are none."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        create = libc.timerfd_create
        settime = libc.timerfd_settime
    except (OSError, AttributeError):
        return None
    create.argtypes = [ctypes.c_int, ctypes.c_int]
    create.restype = ctypes.c_int
    settime.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.POINTER(_Itimerspec), ctypes.c_void_p]
    settime.restype = ctypes.c_int
    return create, settime


_TIMERFD = _load_timerfd()


class TimerFdClock(_Ticker):
    """Calls ``tick()`` on the event loop every ``period`` seconds, timed by a Linux timerfd.

    The kernel keeps the periodic deadlines (drift-free, to the microsecond) and the loop wakes on
    the timer's file descriptor like on a socket: one wake-up per tick, no thread and no hand-over
    through the loop's self-pipe. That costs a third to a half less CPU per tick than ``ThreadClock``
    (``python benchmarks/event_loop_floor.py --clock``). When the loop was held up for more than a period,
    the timer reports how many deadlines passed: ``tick()`` runs once and the rest count as
    ``missed`` (no burst of catch-up ticks); with ``catch_up`` n, up to n passed deadlines each get
    their (late) tick before the rest count as missed. (``ThreadClock``'s thread keeps handing
    ticks over while the loop is held up, and they all run late, back to back.)
    """

    _fd = -1

    def start(self) -> None:
        """Arm the timer: the first tick comes one period from now (OSError where Linux's timerfd
        is not available; ``tick_clock`` chooses this clock only where it is)."""
        if _TIMERFD is None:
            raise OSError("timerfd is not available on this platform")
        create, settime = _TIMERFD
        fd = create(_CLOCK_MONOTONIC, os.O_NONBLOCK | os.O_CLOEXEC)
        if fd < 0:
            raise OSError(ctypes.get_errno(), "timerfd_create failed")
        seconds, nanoseconds = divmod(round(self.period * 1e9), 1_000_000_000)
        every = _Timespec(seconds, nanoseconds)
        if settime(fd, 0, ctypes.byref(_Itimerspec(every, every)), None) != 0:
            errno = ctypes.get_errno()
            os.close(fd)
            raise OSError(errno, "timerfd_settime failed")
        self._fd = fd
        self._loop.add_reader(fd, self._expired)

    def stop(self) -> None:
        """Disarm and close the timer (on the loop's thread)."""
        if self._fd < 0:
            return
        fd, self._fd = self._fd, -1
        self._loop.remove_reader(fd)
        os.close(fd)

    def _expired(self) -> None:
        try:
            count = int.from_bytes(os.read(self._fd, 8), sys.byteorder)
        except BlockingIOError:  # woken without an expiration: nothing to do
            return
        ticks = min(count, self.catch_up)
        self.missed += count - ticks
        for _ in range(ticks):
            self._tick()


def tick_clock(
    period: float, tick: Callable[[], None], loop: asyncio.AbstractEventLoop, *, catch_up: int = 1
) -> TickClock:
    """The cheapest precise clock here: a ``TimerFdClock`` on Linux, else a ``ThreadClock``."""
    if _TIMERFD is not None:
        return TimerFdClock(period, tick, loop, catch_up=catch_up)
    return ThreadClock(period, tick, loop, catch_up=catch_up)
