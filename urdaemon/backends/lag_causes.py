"""What most likely held the event loop up when cycles were missed: CPU steal (a virtual machine's
host gave its CPU to others), other processes keeping the CPUs busy, or a long garbage collection.

Read only when a lag warning is due (``timing.LagLog``, at most once a minute): ``/proc/stat``'s
counters since the last reading, this process's CPU time, and the longest collection ``gc.callbacks``
saw end within the lag. Where ``/proc`` is missing (not Linux), only the collections are known.
"""

from __future__ import annotations

import gc
import os
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["GcWatch", "LagCauses", "gc_watch"]

STEAL_SHARE = 0.05
"""CPU steal above this share of the CPU time since the last reading is named."""
OTHERS_SHARE = 0.5
"""Other processes' share of all CPUs above which they are named."""
GC_PAUSE_S = 0.01
"""A garbage collection at least this long is named."""
KEPT = 16
"""Long collections remembered (a lag names the longest that ended within it)."""


class GcWatch:
    """The long garbage collections (:data:`GC_PAUSE_S` or more) and when each ended, the last
    :data:`KEPT` of them (a ``gc.callbacks`` entry: a clock read per collection, nothing else kept for
    short ones). A lag names only a collection that ended within it: the one that freezes the start-up
    objects, before any cycle runs, is no cause of a lag minutes later."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._started = 0.0
        self.long: deque[tuple[float, float]] = deque(maxlen=KEPT)
        """(ended at on ``clock``, seconds taken) of each long collection, oldest first."""
        self._installed = False

    def install(self) -> None:
        """Watch every collection of this process (once)."""
        if not self._installed:
            gc.callbacks.append(self._on_gc)
            self._installed = True

    def _on_gc(self, phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            self._started = time.perf_counter()
            return
        took = time.perf_counter() - self._started
        if took >= GC_PAUSE_S:
            self.long.append((self._clock(), took))

    def longest_since(self, since: float) -> float:
        """Seconds the longest long collection that ended at ``since`` or later took (0 if none)."""
        return max((took for ended, took in self.long if ended >= since), default=0.0)


gc_watch = GcWatch()
"""The process's one watch (``gc.callbacks`` is process-wide)."""


class LagCauses:
    """Names the likely cause of a hold-up from what changed since the last ``describe``."""

    def __init__(
        self,
        *,
        proc_stat: Path = Path("/proc/stat"),
        own_cpu_s: Any = None,
        watch: GcWatch | None = None,
    ) -> None:
        self._proc_stat = proc_stat
        self._own_cpu_s = own_cpu_s if own_cpu_s is not None else _own_cpu_s
        self._watch = gc_watch if watch is None else watch
        self._watch.install()
        self._last = self._sample()

    def _sample(self) -> tuple[list[int], float] | None:
        counters = _cpu_counters(self._proc_stat)
        return None if counters is None else (counters, self._own_cpu_s())

    def describe(self, since: float) -> str:
        """The likely causes of a lag that began at ``since`` (the watch's clock, ``time.monotonic``):
        the CPU's use since the last call and the longest collection that ended since ``since``, as one
        clause of a log line."""
        causes: list[str] = []
        now = self._sample()
        last, self._last = self._last, now
        if now is not None and last is not None:
            causes += _cpu_causes(last, now)
        pause = self._watch.longest_since(since)
        if pause >= GC_PAUSE_S:
            causes.append(f"a garbage collection took {pause * 1e3:.0f} ms")
        if not causes:
            return (
                "no CPU steal, busy CPUs or long garbage collection seen, so likely a slow callback on "
                "the event loop (PYTHONASYNCIODEBUG=1 names callbacks over 100 ms)"
            )
        return "likely cause: " + "; ".join(causes)


def _cpu_causes(last: tuple[list[int], float], now: tuple[list[int], float]) -> list[str]:
    """CPU steal and other processes' load between two samples of (counters, own CPU seconds)."""
    delta = [b - a for a, b in zip(last[0], now[0], strict=False)]
    total = sum(delta)
    if total <= 0:
        return []
    causes = []
    # user nice system idle iowait irq softirq steal (guest and guest_nice are within user and nice)
    steal = delta[7] if len(delta) > 7 else 0
    if steal / total > STEAL_SHARE:
        causes.append(f"CPU steal {steal / total:.0%} (the virtual machine's host gave its CPU to others)")
    idle = delta[3] + (delta[4] if len(delta) > 4 else 0)
    busy = total - idle - steal
    own = (now[1] - last[1]) * _ticks_per_second()
    others = (busy - own) / total
    if others > OTHERS_SHARE:
        causes.append(
            f"other processes kept the CPUs {others:.0%} busy ({os.cpu_count() or 1} cores; "
            f"this daemon {max(0.0, own / total):.0%})"
        )
    return causes


def _cpu_counters(path: Path) -> list[int] | None:
    """The all-CPU line of ``/proc/stat`` as integers (clock ticks), or None."""
    try:
        with path.open(encoding="ascii") as f:
            line = f.readline()
    except OSError:
        return None
    fields = line.split()
    if not fields or fields[0] != "cpu":
        return None
    try:
        return [int(v) for v in fields[1:9]]
    except ValueError:
        return None


def _own_cpu_s() -> float:
    times = os.times()
    return times.user + times.system


def _ticks_per_second() -> float:
    try:
        return float(os.sysconf("SC_CLK_TCK"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not Unix
        return 100.0
