"""No flood stalls the fake controller: clients writing as fast as they can on every port it serves
(and never reading) cost it neither cycles nor its other services."""

from __future__ import annotations

import contextlib
import struct
import subprocess
import sys
from collections.abc import Iterator

import pytest

from tests.fakeur.test_controller import Link, fake
from urdaemon.fakeur.controller import FakePorts
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols._buffer import Side

pytestmark = pytest.mark.timeout(120)

CYCLES = 1500
"""Controller cycles (3 s at 500 Hz) that must run while every port is flooded."""
MAX_BACKLOG = 4 << 20
"""Bytes the fake may hold unsent for a client that does not read (it skips messages past 1 MiB)."""


def _rtde_requests() -> bytes:
    """Controller-version requests back to back (uint16 size 3, type 'v'), each answered."""
    return struct.pack(">HB", 3, ord("v")) * 4000


FLOODS = {
    "dashboard": b"robotmode\n" * 1000,
    "primary": b"no_such_thing\nstop program\n" * 500,
    "secondary": b"no_such_thing\n" * 1000,
    "realtime": b"no_such_thing\n" * 1000,
    "rtde": _rtde_requests(),
}

FLOODER = """
import socket, sys, threading
address, stop_port = sys.argv[1], int(sys.argv[2])
floods = [(int(port), bytes.fromhex(data)) for port, data in zip(sys.argv[3::2], sys.argv[4::2])]
stop = threading.Event()
sent = {}
def flood(port, data):
    sent[port] = 0
    try:
        with socket.create_connection((address, port), timeout=5.0) as sock:
            sock.settimeout(0.2)
            while not stop.is_set():
                try:
                    sent[port] += sock.send(data)
                except TimeoutError:  # not read: flow control, as it should be
                    continue
    except OSError:  # refused: fine
        pass
threads = [threading.Thread(target=flood, args=f) for f in floods]
for t in threads:
    t.start()
print("flooding", flush=True)
sys.stdin.readline()
stop.set()
for t in threads:
    t.join()
print(" ".join(f"{port}={n}" for port, n in sorted(sent.items())), flush=True)
"""
"""A flooding client in a process of its own (threads here would take the test loop's GIL)."""


@contextlib.contextmanager
def flooding(address: str, ports: FakePorts) -> Iterator[subprocess.Popen[str]]:
    args = [sys.executable, "-c", FLOODER, address, "0"]
    for name, data in FLOODS.items():
        args += [str(getattr(ports, name, 30003)), data[:4096].hex()]
    proc = subprocess.Popen(args, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == "flooding"
        yield proc
    finally:
        proc.communicate("stop\n", timeout=30)


async def test_a_client_flooding_every_port_stalls_neither_the_clock_nor_the_dashboard() -> None:
    """Reproduction: five clients write requests and garbage lines as fast as the kernel takes them on
    29999/30001/30002/30003/30004 and read nothing. Before, the fake parsed and answered a whole 64 KiB
    read at a time (thousands of lines) inside one callback and buffered every answer for the client
    that never reads: its clock missed hundreds of ticks and the buffers grew without bound."""
    async with fake() as controller:
        start = controller.cycles
        link = await Link.open(dash.DashboardConnection(Side.DAEMON), controller.address, 29999)
        await link.next(dash.Banner)
        with flooding(controller.address, controller.ports):
            answers = 0
            for _ in range(CYCLES // 10 + 1):  # bounded; each turn waits for a reply and 10 cycles
                await link.send(dash.GetRobotMode())
                assert (await link.next(dash.RobotModeReply)).mode is not None
                answers += 1
                if controller.cycles - start >= CYCLES:
                    break
                await controller.cycles_pass(10, timeout=100.0)
            # a stalled fake (the code before: ~1000 cycles in 7 minutes) never gets here within the
            # test's timeout; how many ticks a busy machine costs the clock is not this test's business
            assert controller.cycles - start >= CYCLES
            backlog = max(
                (
                    w.transport.get_write_buffer_size()
                    for ws in controller.connections.writers.values()
                    for w in ws
                    if w.transport is not None
                ),
                default=0,
            )
        link.close()
        assert answers > 0
        assert backlog <= MAX_BACKLOG, "replies pile up for a client that does not read"
