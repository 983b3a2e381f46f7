"""The floor under any Python driver's cycle: one wake-up, one read, one write per robot package.

    python benchmarks/event_loop_floor.py            # asyncio, uvloop (if installed), a bare selector
    python benchmarks/event_loop_floor.py --clock    # the fake's tick clocks: a thread or a timerfd

A sender process writes a 560-byte package (the size of the daemon's RTDE output package) to each of
N connections every 2 ms, each connection at its own phase (independent robots); the receiver answers
every package with 28 bytes (a servoj frame) and does nothing else. What the receiver spends per
package is what the event loop and the kernel cost before any decoding, control or publishing: the
part of the 0.04 CPU-s/s budget per robot that no change to urdaemon's own code can win back.

``--clock`` measures the other side of the same wire: what it costs the fake controllers' process
to be woken ``robots`` times per 2 ms (spread phases) by ``ThreadClock`` (a thread sleeping to
deadlines, handing each tick to the loop) and by ``TimerFdClock`` (the loop wakes on a timerfd),
doing nothing else per tick.
"""

from __future__ import annotations

import asyncio
import os
import selectors
import socket
import sys
import time
from typing import Any

PACKAGE = b"x" * 560
REPLY = b"y" * 28
PERIOD_S = 0.002
WINDOW_S = 4.0


def send(port: int, robots: int, seconds: float) -> None:
    """The sender: ``robots`` connections, one package each per period at evenly spread phases."""
    socks = [socket.create_connection(("127.0.0.1", port)) for _ in range(robots)]
    for sock in socks:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.setblocking(False)
    tick = time.monotonic()
    end = tick + seconds
    while tick < end:
        for i, sock in enumerate(socks):
            delay = tick + i * PERIOD_S / robots - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            try:
                sock.send(PACKAGE)
                while sock.recv(65536):
                    pass
            except BlockingIOError:
                pass
            except OSError:
                os._exit(0)
        tick += PERIOD_S
    os._exit(0)


class Echo(asyncio.Protocol):
    """Answers every read with one frame."""

    packages = 0

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport: Any = transport  # uvloop's transports are not asyncio.WriteTransport subclasses

    def data_received(self, data: bytes) -> None:
        Echo.packages += 1
        self.transport.write(REPLY)


async def serve_asyncio(server_sock: socket.socket) -> tuple[float, int]:
    """CPU seconds and packages over the window, on the running loop."""
    loop = asyncio.get_running_loop()
    server = await loop.create_server(Echo, sock=server_sock)
    await asyncio.sleep(0.5)
    cpu, count = time.process_time(), Echo.packages
    await asyncio.sleep(WINDOW_S)
    server.close()
    return time.process_time() - cpu, Echo.packages - count


def serve_selector(server_sock: socket.socket, robots: int) -> tuple[float, int]:
    """The same with a bare ``selectors`` loop: no event loop machinery at all."""
    conns = [server_sock.accept()[0] for _ in range(robots)]
    selector = selectors.DefaultSelector()
    for conn in conns:
        conn.setblocking(False)
        selector.register(conn, selectors.EVENT_READ)
    start = time.monotonic()
    packages, cpu0, count0 = 0, 0.0, 0
    while time.monotonic() - start < WINDOW_S + 0.5:
        if not cpu0 and time.monotonic() - start > 0.5:
            cpu0, count0 = time.process_time(), packages
        for key, _ in selector.select(0.1):
            ready: Any = key.fileobj
            ready.recv(65536)
            ready.send(REPLY)
            packages += 1
    return time.process_time() - cpu0, packages - count0


def measure(kind: str, robots: int) -> tuple[float, float]:
    """(CPU-s/s per robot, µs per package) for ``kind`` with ``robots`` connections."""
    server_sock = socket.socket()
    server_sock.bind(("127.0.0.1", 0))
    server_sock.listen()
    port = server_sock.getsockname()[1]
    pid = os.fork()
    if pid == 0:
        time.sleep(0.2)
        send(port, robots, WINDOW_S + 1.5)
    try:
        if kind == "selector":
            cpu, count = serve_selector(server_sock, robots)
        elif kind == "uvloop":
            import uvloop

            Echo.packages = 0
            cpu, count = uvloop.run(serve_asyncio(server_sock))
        else:
            Echo.packages = 0
            cpu, count = asyncio.run(serve_asyncio(server_sock))
    finally:
        os.waitpid(pid, 0)
        server_sock.close()
    return cpu / WINDOW_S / robots, cpu / max(count, 1) * 1e6


def measure_clock(kind: str, robots: int) -> tuple[float, float, int]:
    """(CPU-s/s per robot, µs per tick, missed) for a ``kind`` clock ticking ``robots`` × 500 Hz."""
    from urdaemon.backends.clock import ThreadClock, TimerFdClock

    async def run() -> tuple[float, float, int]:
        loop = asyncio.get_running_loop()
        ticks = [0]

        def tick() -> None:
            ticks[0] += 1

        clock_type = ThreadClock if kind == "thread" else TimerFdClock
        clock = clock_type(PERIOD_S / robots, tick, loop)
        clock.start()
        try:
            await asyncio.sleep(0.5)  # settle
            cpu0, ticks0 = time.process_time(), ticks[0]
            await asyncio.sleep(WINDOW_S)
            cpu, count = time.process_time() - cpu0, ticks[0] - ticks0
        finally:
            clock.stop()
        return cpu / WINDOW_S / robots, cpu / max(count, 1) * 1e6, clock.missed

    return asyncio.run(run())


def main() -> None:
    """Every loop kind at 1, 4 and 8 robots (or, with ``--clock``, both tick clocks)."""
    if "--clock" in sys.argv[1:]:
        print(f"{os.cpu_count()} cores, Python {sys.version.split()[0]}; one tick per robot every 2 ms")
        print("| clock | robots | CPU-s/s per robot | µs per tick | missed |")
        print("| --- | --- | --- | --- | --- |")
        for kind in ("thread", "timerfd"):
            for robots in (1, 4, 8, 16):
                per_robot, per_tick, missed = measure_clock(kind, robots)
                print(f"| {kind} | {robots} | {per_robot:.4f} | {per_tick:.1f} | {missed} |", flush=True)
        return
    kinds = ["asyncio", "selector"]
    try:
        import uvloop  # noqa: F401

        kinds.insert(1, "uvloop")
    except ImportError:
        print("uvloop is not installed: skipped", file=sys.stderr)
    print(
        f"{os.cpu_count()} cores, Python {sys.version.split()[0]}; 560 B in, 28 B out, every 2 ms per robot"
    )
    print("| loop | robots | CPU-s/s per robot | µs per package |")
    print("| --- | --- | --- | --- |")
    for kind in kinds:
        for robots in (1, 4, 8):
            per_robot, per_package = measure(kind, robots)
            print(f"| {kind} | {robots} | {per_robot:.4f} | {per_package:.1f} |", flush=True)


if __name__ == "__main__":
    main()
