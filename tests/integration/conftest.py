"""Fixtures: a daemon running in the test's own event loop, and a client connected to it."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

import pytest

from tests.helpers import free_tcp_port
from urdaemon.cell import parse_cell
from urdaemon.client import Client
from urdaemon.daemon import Daemon

ROOT = Path(__file__).resolve().parents[2]

TWO_MOCKS = """
cell: testcell
robots:
  - name: alice
    model: ur10e
    backend: mock
    pose: {xyz: [0.5, 0.0, 0.0]}
    mock: {initial_positions: [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]}
    motion: {stream_timeout: 0.1}
  - name: bob
    model: ur5
    backend: mock
    pose: {xyz: [-0.5, 0.0, 0.0], rpy: [0.0, 0.0, 3.141592653589793]}
    mock: {initial_positions: [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]}
"""


@asynccontextmanager
async def running_daemon(
    text: str, base_dir: Path = ROOT / "configs", endpoint: str | None = None
) -> AsyncIterator[tuple[Daemon, Client]]:
    """Start a daemon for cell-file ``text`` in this loop, listening on ``endpoint`` (a free loopback
    TCP port if None); yield it with a client connected there.

    A port that was free a moment ago can be taken before the daemon listens on it (by another run of
    the suite, or as the source port of any connection): then, when the port was ours to choose, the
    daemon starts again on another (at most ``PORT_TRIES`` times).
    """
    for attempt in range(1, PORT_TRIES + 1):
        listen = endpoint or f"tcp/127.0.0.1:{free_tcp_port()}"
        daemon = Daemon(parse_cell(text, base_dir=base_dir), listen=(listen,))
        stop = asyncio.Event()
        task = asyncio.create_task(daemon.run(stop))
        connecting = asyncio.create_task(Client.connect(listen))
        await asyncio.wait({task, connecting}, return_when=asyncio.FIRST_COMPLETED)
        if not task.done():
            break
        # the daemon ended before a client could connect: it could not start
        connecting.cancel()
        with contextlib.suppress(BaseException):
            client = await connecting
            await client.close()
        error = task.exception()
        if endpoint is None and attempt < PORT_TRIES and error is not None and _port_taken(error):
            continue
        if error is not None:
            raise error
        raise AssertionError("the daemon stopped before it served")
    try:
        client = await connecting
        try:
            for robot in daemon.cell.robots:
                await client.robot(robot.name, timeout=10.0)
            yield daemon, client
        finally:
            await client.close()
    finally:
        stop.set()
        await asyncio.wait_for(task, 20.0)


PORT_TRIES = 3


def _port_taken(error: BaseException) -> bool:
    return "Address already in use" in str(error) or "os error 98" in str(error)


@pytest.fixture
async def cell() -> AsyncIterator[tuple[Daemon, Client]]:
    """alice (UR10e, 500 Hz) and bob (UR5, CB3 at 125 Hz) on the mock backend."""
    async with running_daemon(TWO_MOCKS) as pair:
        yield pair
