"""Late and missed cycles of two robots while a client floods the daemon with wildcard queries.

    python benchmarks/query_flood.py                 # 10 s per scenario
    python benchmarks/query_flood.py --seconds 30

A daemon serving two 500 Hz mock robots (alice, bob) runs in this process; a client process
connected over loopback TCP asks ``get(KEY)`` in a loop, as fast as the replies come, for
``--seconds``. For each scenario (no flood, ``**``, ``flood/alice/**``) the table gives the queries
that ended, the replies they got, the daemon process's CPU time (every thread: Zenoh's included),
and each robot's cycles run, missed and late over the window (the backends' own counters, as
``cycle_stats`` reports them); with ``--probe``, also the loop's worst turn (a task turning the loop
as fast as it can: the longest any one callback, or a thread holding the GIL, held every robot's
cycle; it costs a core, so the CPU column then includes it). Late cycles of bob while only alice's
keys are flooded are what must not happen (docs/keys.md "In flight").
"""

from __future__ import annotations

import argparse
import asyncio
import os
import socket
import sys
import time
from pathlib import Path
from typing import Any

from urdaemon.cell import parse_cell
from urdaemon.daemon import Daemon

ROOT = Path(__file__).resolve().parents[1]
CELL = """
cell: flood
robots:
  - name: alice
    model: ur10e
    backend: mock
    mock: {initial_positions: [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]}
  - name: bob
    model: ur10e
    backend: mock
    pose: {xyz: [1.0, 0.0, 0.0]}
    mock: {initial_positions: [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]}
"""
SCENARIOS = ("", "**", "flood/alice/**")
"""The keys flooded ("": none, the baseline)."""


def flooder(endpoint: str, key: str, seconds: float) -> None:
    """The client, in a process of its own: ``get(key)`` in a loop for ``seconds``; prints the
    queries and the replies."""
    import zenoh

    from urdaemon.publish.session_config import zenoh_config

    session: Any = zenoh.open(zenoh_config("peer", [], [endpoint]))
    queries = replies = 0
    try:
        print("ready", flush=True)
        sys.stdin.readline()
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            replies += len(list(session.get(key, timeout=2.0)))
            queries += 1
    finally:
        session.close()
    print(f"{queries} {replies}", flush=True)


class Probe:
    """Turns the loop as fast as it can; ``worst`` is the longest gap between two turns."""

    def __init__(self) -> None:
        self.worst = 0.0

    async def run(self, seconds: float) -> None:
        last = time.perf_counter()
        end = last + seconds
        while last < end:
            await asyncio.sleep(0)
            now = time.perf_counter()
            self.worst = max(self.worst, now - last)
            last = now


async def scenario(daemon: Daemon, endpoint: str, key: str, seconds: float, probe: bool) -> dict[str, Any]:
    """One window of ``seconds`` with ``key`` flooded ("" none): the counts."""
    proc = None
    if key:
        proc = await asyncio.create_subprocess_exec(
            sys.executable,
            __file__,
            "--flooder",
            endpoint,
            "--key",
            key,
            "--seconds",
            str(seconds),
            stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE,
        )
        assert proc.stdin is not None
        assert proc.stdout is not None
        if (await asyncio.wait_for(proc.stdout.readline(), 60.0)).strip() != b"ready":
            raise RuntimeError("the flooder did not start")
    before = {rt.backend.name: rt.backend.statistics() for rt in daemon.runtimes}
    turns = Probe()
    cpu = _cpu_s()
    if proc is not None:
        assert proc.stdin is not None
        proc.stdin.write(b"go\n")
        await proc.stdin.drain()
    if probe:
        await turns.run(seconds)
    else:
        await asyncio.sleep(seconds)
    cpu = _cpu_s() - cpu
    after = {rt.backend.name: rt.backend.statistics() for rt in daemon.runtimes}
    row: dict[str, Any] = {
        "key": key or "(none)",
        "queries": 0,
        "replies": 0,
        "worst_ms": turns.worst * 1e3,
        "cpu_s": cpu,
    }
    if proc is not None:
        assert proc.stdout is not None
        line = (await asyncio.wait_for(proc.stdout.readline(), 60.0)).split()
        row["queries"], row["replies"] = int(line[0]), int(line[1])
        await asyncio.wait_for(proc.wait(), 30.0)
    for name in after:
        a, b = after[name], before[name]
        row[name] = (a.cycles - b.cycles, a.missed_cycles - b.missed_cycles, a.late_cycles - b.late_cycles)
    return row


def _cpu_s() -> float:
    """This process's CPU time (the daemon's, every thread; not the flooder's)."""
    times = os.times()
    return times.user + times.system


async def measure(
    seconds: float, keys: tuple[str, ...] = SCENARIOS, probe: bool = False
) -> list[dict[str, Any]]:
    """Every scenario, one after the other, against one daemon."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        endpoint = f"tcp/127.0.0.1:{sock.getsockname()[1]}"
    daemon = Daemon(parse_cell(CELL, base_dir=ROOT / "configs"), listen=(endpoint,))
    stop = asyncio.Event()
    serving = asyncio.create_task(daemon.run(stop))
    rows = []
    try:
        for _ in range(100):  # bounded: the robots cycle within a second of the start
            if daemon.runtimes and all(rt.backend.statistics().cycles > 500 for rt in daemon.runtimes):
                break
            await asyncio.sleep(0.1)
        for key in keys:
            rows.append(await scenario(daemon, endpoint, key, seconds, probe))
    finally:
        stop.set()
        await asyncio.wait_for(serving, 20.0)
    return rows


def main() -> None:
    """Measure every scenario and print a table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0] if __doc__ else None)
    parser.add_argument("--seconds", type=float, default=10.0, help="length of each scenario's window")
    parser.add_argument("--probe", action="store_true", help="also measure the loop's worst turn")
    parser.add_argument("--flooder", metavar="ENDPOINT", help=argparse.SUPPRESS)
    parser.add_argument("--key", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.flooder:
        flooder(args.flooder, args.key, args.seconds)
        return
    rows = asyncio.run(measure(args.seconds, probe=args.probe))
    print(
        f"{'flooded':<16} {'queries':>8} {'replies':>8} {'daemon CPU':>11} {'loop worst':>11}  "
        "per robot: cycles missed late"
    )
    for row in rows:
        robots = "  ".join(
            f"{n} {c} {m} {late}" for n, (c, m, late) in ((k, row[k]) for k in ("alice", "bob"))
        )
        print(
            f"{row['key']:<16} {row['queries']:>8} {row['replies']:>8} {row['cpu_s']:>9.2f} s "
            f"{row['worst_ms']:>8.1f} ms  {robots}"
        )


if __name__ == "__main__":
    main()
