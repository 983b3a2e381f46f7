"""The floor under any Python driver's cycle: one wake-up, one read, one write per robot package.

    python benchmarks/event_loop_floor.py            # asyncio, uvloop (if installed), a bare selector
    python benchmarks/event_loop_floor.py --publish  # the same, each package also published over Zenoh
    python benchmarks/event_loop_floor.py --publish --read-only  # 1 robot, published, no reply
    python benchmarks/event_loop_floor.py --clock    # the fake's tick clocks: a thread or a timerfd

A sender process writes a 560-byte package (the size of the daemon's RTDE output package) to each of
N connections every 2 ms, each connection at its own phase (independent robots); the receiver answers
every package with 28 bytes (a servoj frame) and does nothing else. What the receiver spends per
package is what the event loop and the kernel cost before any decoding, control or publishing: the
part of the 0.04 CPU-s/s budget per robot that no change to urdaemon's own code can win back.

``--publish`` adds the third thing every cycle of the daemon does: the receiver also puts a 400-byte
sample (the size of ``joint_states``) per package on a Zenoh publisher of its robot, with the
daemon's state stream settings, to a subscriber in a third process; once over loopback TCP, once
with the cheapest transport measured (low latency at both ends, over a Unix socket). That is the
whole cycle of a controlling daemon with nothing decoded, computed or encoded: the floor under the
full-control target, measured with three processes on the machine as in control_loop.py. With
``--read-only`` as well, one robot whose packages are published and not answered: the floor under
the read-only target (a watched robot sends nothing back).

``--clock`` measures the other side of the same wire: what it costs the fake controllers' process
to be woken ``robots`` times per 2 ms (spread phases) by ``ThreadClock`` (a thread sleeping to
deadlines, handing each tick to the loop) and by ``TimerFdClock`` (the loop wakes on a timerfd),
doing nothing else per tick.
"""

from __future__ import annotations

import asyncio
import os
import selectors
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, ClassVar

PACKAGE = b"x" * 560
REPLY = b"y" * 28
SAMPLE = b"z" * 400
PERIOD_S = 0.002
WINDOW_S = 4.0
SETTLE_S = 0.5
ZENOH_START_S = 2.0  # with --publish: the session opens and the subscriber connects before packages flow
TRANSPORTS = ("loopback TCP", "low latency + Unix socket")


def send(port: int, robots: int, seconds: float, delay: float = 0.2) -> None:
    """The sender: ``robots`` connections, one package each per period at evenly spread phases."""
    time.sleep(delay)
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


class Publishers:
    """With ``--publish``: one Zenoh session and one publisher per robot, as the daemon has."""

    def __init__(self, transport: str, robots: int, seconds: float = ZENOH_START_S + WINDOW_S + 2.0) -> None:
        import zenoh

        from urdaemon.publish.node import declare_state_publisher
        from urdaemon.publish.session_config import zenoh_config

        self.sockets = tempfile.mkdtemp(prefix="loop-floor-")
        fast = transport != TRANSPORTS[0]
        if fast:
            endpoint = f"unixsock-stream/{self.sockets}/zenoh.sock"
        else:
            probe = socket.socket()
            probe.bind(("127.0.0.1", 0))
            endpoint = f"tcp/127.0.0.1:{probe.getsockname()[1]}"
            probe.close()
        self.session: Any = zenoh.open(zenoh_config("peer", [endpoint], [], low_latency=fast))
        self.publishers: list[Any] = [
            declare_state_publisher(self.session, f"bench/{index}/state") for index in range(robots)
        ]
        script = str(Path(__file__).with_name("zenoh_put.py"))  # its subscriber: counts samples
        flag = str(int(fast))
        command = [sys.executable, script, "--subscribe", endpoint, flag, str(seconds)]
        self.subscriber = subprocess.Popen(command)
        deadline = time.monotonic() + 20.0
        while not all(pub.matching_status.matching for pub in self.publishers):  # the subscriber is there
            if time.monotonic() > deadline:
                raise RuntimeError("the subscriber did not appear within 20 s")
            time.sleep(0.05)

    def close(self) -> int:
        """Wait for the subscriber (it ends on its own after ``seconds``), end the session; the
        subscriber's exit status."""
        try:
            return self.subscriber.wait(30)
        finally:
            self.session.close()
            shutil.rmtree(self.sockets, ignore_errors=True)


class Echo(asyncio.Protocol):
    """Answers every read with one frame (and, with ``--publish``, puts one sample)."""

    packages = 0
    connections = 0
    publishers: ClassVar[list[Any]] = []
    reply = True

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport: Any = transport  # uvloop's transports are not asyncio.WriteTransport subclasses
        self.publisher = Echo.publishers[Echo.connections] if Echo.publishers else None
        Echo.connections += 1

    def data_received(self, data: bytes) -> None:
        Echo.packages += 1
        if Echo.reply:
            self.transport.write(REPLY)
        if self.publisher is not None:
            self.publisher.put(SAMPLE)


async def serve_asyncio(server_sock: socket.socket, settle: float) -> tuple[float, int]:
    """CPU seconds and packages over the window, on the running loop."""
    loop = asyncio.get_running_loop()
    server = await loop.create_server(Echo, sock=server_sock)
    await asyncio.sleep(settle)
    cpu, count = time.process_time(), Echo.packages
    await asyncio.sleep(WINDOW_S)
    server.close()
    return time.process_time() - cpu, Echo.packages - count


def serve_selector(server_sock: socket.socket, robots: int, publishers: list[Any]) -> tuple[float, int]:
    """The same with a bare ``selectors`` loop: no event loop machinery at all."""
    conns = [server_sock.accept()[0] for _ in range(robots)]
    selector = selectors.DefaultSelector()
    for index, conn in enumerate(conns):
        conn.setblocking(False)
        selector.register(conn, selectors.EVENT_READ, publishers[index] if publishers else None)
    start = time.monotonic()
    packages, cpu0, count0 = 0, 0.0, 0
    while time.monotonic() - start < WINDOW_S + SETTLE_S:
        if not cpu0 and time.monotonic() - start > SETTLE_S:
            cpu0, count0 = time.process_time(), packages
        for key, _ in selector.select(0.1):
            ready: Any = key.fileobj
            ready.recv(65536)
            if Echo.reply:
                ready.send(REPLY)
            if key.data is not None:
                key.data.put(SAMPLE)
            packages += 1
    return time.process_time() - cpu0, packages - count0


def measure(kind: str, robots: int, transport: str | None = None) -> tuple[float, float]:
    """(CPU-s/s per robot, µs per package) for ``kind`` with ``robots`` connections; with a
    ``transport`` (one of TRANSPORTS) each package is also published over Zenoh."""
    server_sock = socket.socket()
    server_sock.bind(("127.0.0.1", 0))
    server_sock.listen()
    port = server_sock.getsockname()[1]
    delay = ZENOH_START_S if transport else 0.2
    forked = time.monotonic()
    pid = os.fork()
    if pid == 0:  # before any Zenoh thread exists in this process
        send(port, robots, WINDOW_S + SETTLE_S + 1.0, delay)
    publishers = Publishers(transport, robots) if transport else None
    Echo.packages, Echo.connections = 0, 0
    Echo.publishers = publishers.publishers if publishers else []
    settle = max(SETTLE_S, forked + delay + SETTLE_S - time.monotonic())  # packages flow for SETTLE_S first
    try:
        if kind == "selector":
            cpu, count = serve_selector(server_sock, robots, Echo.publishers)
        elif kind == "uvloop":
            import uvloop

            cpu, count = uvloop.run(serve_asyncio(server_sock, settle))
        else:
            cpu, count = asyncio.run(serve_asyncio(server_sock, settle))
    finally:
        os.waitpid(pid, 0)
        server_sock.close()
        if publishers is not None:
            publishers.close()
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
    if "--publish" in sys.argv[1:]:
        Echo.reply = "--read-only" not in sys.argv[1:]
        answer = "28 B out and " if Echo.reply else "no answer, "
        print(
            f"{os.cpu_count()} cores, Python {sys.version.split()[0]}; 560 B in, {answer}"
            f"{len(SAMPLE)} B published over Zenoh, every 2 ms per robot"
        )
        print("| loop | Zenoh transport | robots | CPU-s/s per robot | µs per package |")
        print("| --- | --- | --- | --- | --- |")
        for transport in TRANSPORTS:
            for kind in kinds:
                for robots in (1, 4, 8) if Echo.reply else (1,):
                    per_robot, per_package = measure(kind, robots, transport)
                    print(
                        f"| {kind} | {transport} | {robots} | {per_robot:.4f} | {per_package:.1f} |",
                        flush=True,
                    )
        return
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
