"""Real time of two fake controllers in one process while one of them runs a script flooding a socket.

    python benchmarks/script_flood.py                    # 5 windows of 1 s per scenario
    python benchmarks/script_flood.py --windows 10 --window 2
    PYTHONPATH=/tmp/old python benchmarks/script_flood.py   # the fake of another checkout

Two UR10e fakes (``urdaemon.fakeur``, at a random 127.a.b.0/24) share one clock in this process, ticked
together (``urdaemon fake-robot --phases aligned``). Per scenario, ``quiet`` (both run a program whose
thread counts its cycles and whose main program calls ``sync``), ``write`` (the first one's main
program writes to a socket a listener never reads, in a loop without sleeping) and ``read`` (it reads
from a socket a peer in another process floods, in a loop without sleeping; both as UR's client
library's examples make External Control do), and per ``--window`` seconds of wall time, the table
gives:

- each fake's **share of real time**: cycles run / controller periods passed (the issue asks ≥ 0.95);
- the processor time each fake's cycles used, per cycle (``time.thread_time`` of the event loop's
  thread: what the fake controls; a preempted fake does not count time it did not run);
- whether the flooding program's counting thread ran in every cycle its fake ran;
- the process's processor time per second, and the load average before and after.

The test (tests/fakeur/test_script_flood.py) asserts only the counts and the processor time per cycle;
the share of real time depends on the machine as much as on the fake, so it is measured here.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import importlib.util
import os
import socket
import statistics
import subprocess
import sys
import time
from collections.abc import AsyncIterator, Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

from urdaemon.fakeur.command import share_clock
from urdaemon.fakeur.controller import FakeController
from urdaemon.fakeur.shared_clock import SharedClock

ROOT = Path(__file__).resolve().parents[1]
KINDS = ("quiet", "write", "read")

TICKER = """
  global ticks = 0
  thread ticker():
    while True:
      ticks = ticks + 1
      sync()
    end
  end
  run ticker()
"""
"""A thread of every program here: counts the cycles it runs in."""

WRITER = (
    "def flood():\n"
    + TICKER
    + """
  socket_open("127.0.0.1", {port}, "f")
  while True:
    socket_send_string("0123456789abcdef0123456789abcdef", "f")
  end
end
"""
)
"""Writes to a socket in a tight loop (the peer never reads: the kernel's buffer fills, then the fake's)."""

READER = (
    "def flood():\n"
    + TICKER
    + """
  socket_open("127.0.0.1", {port}, "f")
  while True:
    got = socket_read_byte_list(64, "f")
  end
end
"""
)
"""Reads in a tight loop from a peer that writes as fast as it can: the read never has to wait."""

QUIET = "def quiet():\n" + TICKER + "  while True:\n    sync()\n  end\nend\n"
"""The program of a fake that does not flood."""

FLOOD_SERVER = """
import socket, sys
server = socket.socket()
server.bind(("127.0.0.1", 0))
server.listen(1)
print(server.getsockname()[1], flush=True)
conn, _ = server.accept()
data = b"x" * 65536
try:
    while True:
        conn.sendall(data)
except OSError:
    pass
"""
"""A peer that writes as fast as the kernel takes it, in a process of its own (not the fakes' GIL)."""


@contextlib.contextmanager
def silent_listener() -> Iterator[int]:
    """A listening socket that never accepts nor reads (the kernel completes the connection); its port."""
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        yield server.getsockname()[1]


@contextlib.contextmanager
def flooding_peer() -> Iterator[int]:
    """A process writing as fast as it can to whoever connects to its port; the port."""
    proc = subprocess.Popen([sys.executable, "-c", FLOOD_SERVER], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        yield int(proc.stdout.readline())
    finally:
        proc.kill()
        proc.wait(timeout=10)


def program(kind: str, port: int) -> tuple[str, str]:
    """The name and text of the first fake's program in scenario ``kind``."""
    if kind == "quiet":
        return "quiet", QUIET
    return "flood", (WRITER if kind == "write" else READER).format(port=port)


@contextlib.contextmanager
def peer(kind: str) -> Iterator[int]:
    """The socket peer scenario ``kind``'s program talks to (a port; 0 when it talks to none)."""
    if kind == "read":
        with flooding_peer() as port:
            yield port
    elif kind == "write":
        with silent_listener() as port:
            yield port
    else:
        yield 0


@dataclass
class CycleCpu:
    """Processor time one fake's cycles used (its clock tick: programs, arm, streams)."""

    period: float
    cycles: int = 0
    seconds: float = 0.0
    over: int = 0
    """Cycles that used more processor time than a controller period."""
    most: float = 0.0

    def add(self, used: float) -> None:
        self.cycles += 1
        self.seconds += used
        if used > self.period:
            self.over += 1
        self.most = max(self.most, used)

    def reset(self) -> None:
        self.cycles = self.over = 0
        self.seconds = self.most = 0.0

    @property
    def per_cycle(self) -> float:
        return self.seconds / self.cycles if self.cycles else 0.0


@contextlib.contextmanager
def cycle_cpu(clock: SharedClock, fakes: tuple[FakeController, ...]) -> Iterator[list[CycleCpu]]:
    """Count the processor time of each of ``fakes``' ticks on ``clock`` (in the order of ``fakes``),
    by wrapping the ticks in its slots; the clock gets its own ticks back on leaving, before a fake
    closes (it removes its tick by identity)."""
    counters = [CycleCpu(fake.step_time) for fake in fakes]
    originals = [list(ticks) for ticks in clock.slots]

    def timed(tick: Callable[[], None], counter: CycleCpu) -> Callable[[], None]:
        def run() -> None:
            start = time.thread_time()
            tick()
            counter.add(time.thread_time() - start)

        return run

    owners = {id(fake): counter for fake, counter in zip(fakes, counters, strict=True)}
    for ticks in clock.slots:
        ticks[:] = [timed(tick, owners[id(getattr(tick, "__self__", None))]) for tick in ticks]
    try:
        yield counters
    finally:
        for ticks, kept in zip(clock.slots, originals, strict=True):
            ticks[:] = kept


@contextlib.asynccontextmanager
async def two_fakes(
    pair: tuple[str, str],
) -> AsyncIterator[tuple[FakeController, FakeController, SharedClock]]:
    """Two powered UR10e fakes at ``pair`` on one clock, ticked together; started, closed on leaving."""
    fakes = [FakeController("ur10e", address=address, powered=True) for address in pair]
    clock = share_clock(fakes, "aligned")
    assert clock is not None
    for fake in fakes:
        await fake.start()
    try:
        yield fakes[0], fakes[1], clock
    finally:
        for fake in fakes:
            await fake.close()


def ticks(fake: FakeController) -> int | str:
    """The running program's ``ticks``, or why there is none (the program ended: its error)."""
    script = fake.programs.main
    if script is None:
        return "the program ended"
    if script.run.error is not None:
        return str(script.run.error)
    try:
        return int(script.run.variable("ticks"))
    except KeyError:
        return "no ticks yet"


async def started(fake: FakeController, *, cycles: int = 5000) -> str | None:
    """Wait until ``fake``'s program (submitted) counts its cycles, or it ended; None, or why it does
    not count."""
    seen: list[Any] = []

    def counting() -> bool:
        script = fake.programs.main
        if script is not None and not seen:
            seen.append(script)
        if seen and seen[0].run.done:
            return True
        return isinstance(ticks(fake), int) or (not fake.programs.busy and script is None)

    await fake.until(counting, cycles=cycles)
    if seen and seen[0].run.done:
        return f"the program ended: {seen[0].run.error}"
    if fake.programs.main is None:
        return "the program ended (or was refused) before it counted a cycle"
    return None


@dataclass
class Window:
    seconds: float
    shares: tuple[float, float]
    cpu_per_cycle: tuple[float, float]
    over: tuple[int, int]
    ticks_every_cycle: bool
    process_cpu: float


@dataclass
class Scenario:
    kind: str
    windows: list[Window] = field(default_factory=list)
    failure: str | None = None
    load: tuple[float, float] = (0.0, 0.0)


async def measure(kind: str, windows: int, window: float, pair: tuple[str, str]) -> Scenario:
    """Scenario ``kind``: ``windows`` windows of ``window`` seconds of wall time."""
    scenario = Scenario(kind, load=(os.getloadavg()[0], 0.0))
    with peer(kind) as port:
        async with two_fakes(pair) as (first, second, clock):
            first.programs.submit(*program(kind, port))
            second.programs.submit("quiet", QUIET)
            for fake in (first, second):
                scenario.failure = scenario.failure or await started(fake)
            with cycle_cpu(clock, (first, second)) as cpu:
                for _ in range(windows):
                    scenario.windows.append(await _window(first, second, cpu, window))
                    if scenario.failure is None and not all(
                        isinstance(ticks(f), int) for f in (first, second)
                    ):
                        scenario.failure = f"{ticks(first)} / {ticks(second)}"
    scenario.load = (scenario.load[0], os.getloadavg()[0])
    return scenario


async def _window(
    first: FakeController, second: FakeController, cpu: list[CycleCpu], seconds: float
) -> Window:
    for counter in cpu:
        counter.reset()
    fakes = (first, second)
    cycles = [f.cycles for f in fakes]
    counted = [ticks(f) for f in fakes]
    process, start = time.process_time(), time.perf_counter()
    await asyncio.sleep(seconds)
    elapsed = time.perf_counter() - start
    used = time.process_time() - process
    ran = [f.cycles - c for f, c in zip(fakes, cycles, strict=True)]
    every = True
    for fake, before, count in zip(fakes, counted, ran, strict=True):
        after = ticks(fake)
        every = (
            every and isinstance(before, int) and isinstance(after, int) and abs(after - before - count) <= 1
        )
    return Window(
        elapsed,
        (ran[0] * first.step_time / elapsed, ran[1] * second.step_time / elapsed),
        (cpu[0].per_cycle, cpu[1].per_cycle),
        (cpu[0].over, cpu[1].over),
        every,
        used / elapsed,
    )


def table(scenarios: list[Scenario]) -> str:
    """The markdown table of docs/performance.md: one row per scenario, medians (min) over windows."""
    lines = [
        "| first fake's program | share of real time: flooding fake / other, median (min) | "
        "CPU per cycle, µs: flooding / other (median) | cycles over a period of CPU | "
        "counting thread every cycle | process CPU-s/s | load before → after | program |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for s in scenarios:
        w = s.windows
        shares = [
            f"{statistics.median(x.shares[i] for x in w):.3f} ({min(x.shares[i] for x in w):.3f})"
            for i in (0, 1)
        ]
        cpu = [f"{statistics.median(x.cpu_per_cycle[i] for x in w) * 1e6:.0f}" for i in (0, 1)]
        over = f"{sum(x.over[0] for x in w)} / {sum(x.over[1] for x in w)}"
        every = "yes" if all(x.ticks_every_cycle for x in w) else "no"
        process = f"{statistics.median(x.process_cpu for x in w):.2f}"
        load = f"{s.load[0]:.2f} → {s.load[1]:.2f}"
        state = (s.failure or "running").split(". ")[0]  # the first sentence of an error
        lines.append(
            f"| {s.kind} | {shares[0]} / {shares[1]} | {cpu[0]} / {cpu[1]} | {over} | {every} | {process} "
            f"| {load} | {state} |"
        )
    return "\n".join(lines)


def _hiccups() -> ModuleType:
    """benchmarks/hiccups.py: its free pair of fake addresses."""
    spec = importlib.util.spec_from_file_location("bench_hiccups", ROOT / "benchmarks" / "hiccups.py")
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--windows", type=int, default=5, help="windows per scenario (default 5)")
    parser.add_argument("--window", type=float, default=1.0, help="seconds per window (default 1)")
    parser.add_argument("--kinds", default=",".join(KINDS), help=f"scenarios (default {','.join(KINDS)})")
    args = parser.parse_args()
    hiccups = _hiccups()
    import urdaemon

    print(f"machine: {hiccups.CL.machine()}; urdaemon from {Path(urdaemon.__file__).parent}")
    scenarios = [
        asyncio.run(measure(kind, args.windows, args.window, hiccups.addresses()))
        for kind in args.kinds.split(",")
    ]
    print(table(scenarios))


if __name__ == "__main__":
    main()
