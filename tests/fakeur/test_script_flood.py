"""A script that floods a socket keeps its controller's clock, and every other fake's in the process.

UR's manual (Thread scheduling) gives each thread a time slice of the controller's frame and puts a
thread that used it aside until the next frame. Reproduction (issue 33, point 1): UR's client library's
examples write to the robot in a loop without sleeping, so External Control's read loop always found
data and never waited; the fake let it run for 0.5 s of processor time per cycle, and its clock fell
to about 1 % of real time. A script writing in a tight loop stopped with a runtime error after 100 000
iterations in one cycle.

Real time is counted by the shared clock itself (its timer's ticks, run or skipped because the loop
was held up), not read off a wall clock by the test: a controller keeps real time when it runs a
cycle for (nearly) every period that passed.
"""

from __future__ import annotations

import contextlib
import socket
import subprocess
import sys
from collections.abc import AsyncIterator, Iterator

import pytest

from tests.helpers import fake_address
from urdaemon.fakeur.command import share_clock
from urdaemon.fakeur.controller import FakeController
from urdaemon.fakeur.shared_clock import SharedClock

pytestmark = pytest.mark.timeout(120)

WINDOW = 500
"""Periods (1 s at 500 Hz) over which a fake's cycles are counted against the clock's ticks."""
WINDOWS = 5
"""Windows tried: the check passes when one of them kept real time (a busy machine may cost any one
window its ticks; a stalled fake, at ~1 % of real time, keeps none)."""
REAL_TIME = 0.95
"""The share of the periods that passed in which a controller must have run its cycle."""

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
"""A thread of the flooding program that counts the cycles it runs in."""

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
"""A peer that writes as fast as the kernel takes it, in a process of its own (not the test's GIL)."""


@contextlib.contextmanager
def _silent_listener() -> Iterator[int]:
    """A listening socket that never accepts nor reads: the kernel completes the connection."""
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        yield server.getsockname()[1]


@contextlib.contextmanager
def _flooding_peer() -> Iterator[int]:
    proc = subprocess.Popen([sys.executable, "-c", FLOOD_SERVER], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        yield int(proc.stdout.readline())
    finally:
        proc.kill()
        proc.wait(timeout=10)


@contextlib.asynccontextmanager
async def _two_fakes() -> AsyncIterator[tuple[FakeController, FakeController, SharedClock]]:
    fakes = [FakeController("ur10e", address=fake_address(), powered=True) for _ in range(2)]
    clock = share_clock(fakes, "aligned")
    assert clock is not None
    for fake in fakes:
        await fake.start()
    try:
        yield fakes[0], fakes[1], clock
    finally:
        for fake in fakes:
            await fake.close()


def _ticks(fake: FakeController) -> int:
    script = fake.programs.main
    assert script is not None, "the program ended"
    assert script.run.error is None, script.run.error
    return int(script.run.variable("ticks"))


@pytest.mark.parametrize("kind", ["write", "read"])
async def test_a_flooding_script_keeps_real_time_beside_another_fake(kind: str) -> None:
    peer = _silent_listener() if kind == "write" else _flooding_peer()
    with peer as port:
        async with _two_fakes() as (flooder, other, clock):
            flooder.programs.submit("flood", (WRITER if kind == "write" else READER).format(port=port))
            other.programs.submit("quiet", QUIET)
            for fake in (flooder, other):
                await fake.until(lambda f=fake: _has_ticks(f), cycles=5000)  # type: ignore[misc]
            kept: list[float] = []
            for _ in range(WINDOWS):
                periods = clock.fired + clock.missed
                cycles = (flooder.cycles, other.cycles)
                ticks = (_ticks(flooder), _ticks(other))
                end = periods + WINDOW
                await flooder.until(lambda: clock.fired + clock.missed >= end, cycles=WINDOW)  # noqa: B023
                passed = clock.fired + clock.missed - periods
                ran = (flooder.cycles - cycles[0], other.cycles - cycles[1])
                # the flooding program's other thread ran in every cycle its program was stepped
                assert abs((_ticks(flooder) - ticks[0]) - ran[0]) <= 1
                assert abs((_ticks(other) - ticks[1]) - ran[1]) <= 1
                kept.append(min(ran) / passed)
                if kept[-1] >= REAL_TIME:
                    break
            assert max(kept) >= REAL_TIME, f"share of real time per window: {kept}"


def _has_ticks(fake: FakeController) -> bool:
    script = fake.programs.main
    if script is None:
        return False
    try:
        script.run.variable("ticks")
    except KeyError:
        return False
    return True
