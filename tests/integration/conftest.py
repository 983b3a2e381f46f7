"""Fixtures: a daemon running in the test's own event loop, and a client connected to it."""

from __future__ import annotations

import asyncio
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
    TCP port if None); yield it with a client connected there."""
    endpoint = endpoint or f"tcp/127.0.0.1:{free_tcp_port()}"
    daemon = Daemon(parse_cell(text, base_dir=base_dir), listen=(endpoint,))
    stop = asyncio.Event()
    task = asyncio.create_task(daemon.run(stop))
    try:
        client = await Client.connect(endpoint)
        try:
            for robot in daemon.cell.robots:
                await client.robot(robot.name, timeout=10.0)
            yield daemon, client
        finally:
            await client.close()
    finally:
        stop.set()
        await asyncio.wait_for(task, 20.0)


@pytest.fixture
async def cell() -> AsyncIterator[tuple[Daemon, Client]]:
    """alice (UR10e, 500 Hz) and bob (UR5, CB3 at 125 Hz) on the mock backend."""
    async with running_daemon(TWO_MOCKS) as pair:
        yield pair
