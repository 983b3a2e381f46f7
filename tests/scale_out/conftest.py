"""A site in one process: ``urdaemon router``'s router on an OS-chosen loopback port, the daemons of
configs/scale_out/'s cells as its Zenoh clients, and a client that dials the router.

The router runs in-process (``urdaemon.router.Router``, what ``urdaemon router`` runs): a Zenoh
session in router mode is one more session of this process, beside the daemons' and the client's,
and needs no process of its own. Only the command's signal handling does (test_router_command.py).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
import zenoh

from urdaemon.cell import Cell, parse_cell
from urdaemon.client import Client
from urdaemon.daemon import Daemon
from urdaemon.router import Router, router_config

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = ROOT / "configs" / "scale_out"
CELL_FILES = {"cell_a": CONFIGS / "cell_a.yaml", "cell_b": CONFIGS / "cell_b.yaml"}
START_TIMEOUT_S = 30.0
"""Bound on a daemon's start (its robots' liveliness tokens seen through the router)."""
STOP_TIMEOUT_S = 20.0
DISCOVERY_TRIES = 300
DISCOVERY_PAUSE_S = 0.05
"""Between two liveliness queries of ``wait_alive`` (the client's own discovery polls at 0.1 s)."""


def shipped_cell(name: str, router: str) -> Cell:
    """configs/scale_out/<name>.yaml as shipped, but connecting to ``router`` (the test's router)."""
    data = yaml.safe_load(CELL_FILES[name].read_text(encoding="utf-8"))
    data["zenoh"]["connect"] = [router]
    return parse_cell(yaml.safe_dump(data), base_dir=CONFIGS)


async def open_router(connect: Sequence[str] = ()) -> tuple[Router, str]:
    """A router listening on an OS-chosen loopback port (linked to ``connect``), and that endpoint."""
    router = await Router.open(router_config(["tcp/127.0.0.1:0"], list(connect)))
    locators = await router.locators()
    assert len(locators) == 1, locators
    assert locators[0].startswith("tcp/127.0.0.1:"), locators
    assert not locators[0].endswith(":0"), "the router reports the port the OS chose"
    return router, locators[0]


@dataclass
class Site:
    """What runs: the daemons (by cell name) and the stop that ends them."""

    daemons: dict[str, Daemon] = field(default_factory=dict)
    tasks: dict[str, asyncio.Task[None]] = field(default_factory=dict)
    stop: asyncio.Event = field(default_factory=asyncio.Event)

    def start(self, cell: Cell) -> None:
        daemon = Daemon(cell)
        self.daemons[cell.cell] = daemon
        self.tasks[cell.cell] = asyncio.create_task(daemon.run(self.stop), name=f"daemon {cell.cell}")

    async def close(self) -> None:
        self.stop.set()
        for task in self.tasks.values():
            with contextlib.suppress(Exception):
                await asyncio.wait_for(task, STOP_TIMEOUT_S)


@asynccontextmanager
async def serving(cells: Sequence[Cell]) -> AsyncIterator[Site]:
    """Run a daemon per cell in this loop; stop them all afterwards."""
    site = Site()
    try:
        for cell in cells:
            site.start(cell)
        yield site
    finally:
        await site.close()


async def wait_alive(client: Client, robots: set[str], site: Site, timeout: float = START_TIMEOUT_S) -> None:
    """Wait until ``client`` sees each ``<cell>/<robot>/alive`` token (through the router), or fail
    at once when a daemon ends (it could not reach the router) or after ``timeout`` s."""
    loop = asyncio.get_running_loop()
    seen: set[str] = set()
    all_seen = asyncio.Event()

    def note(key: str) -> None:
        seen.add(key)
        if {f"{r}/alive" for r in robots} <= seen:
            all_seen.set()

    def on_token(sample: Any) -> None:  # a Zenoh thread
        if sample.kind == zenoh.SampleKind.PUT:
            with contextlib.suppress(RuntimeError):  # the loop has closed: nobody waits
                loop.call_soon_threadsafe(note, str(sample.key_expr))

    watch = client.session.liveliness().declare_subscriber("*/*/alive", on_token, history=True)
    waiter = asyncio.ensure_future(all_seen.wait())
    try:
        done, _ = await asyncio.wait(
            {waiter, *site.tasks.values()}, timeout=timeout, return_when=asyncio.FIRST_COMPLETED
        )
    finally:
        waiter.cancel()
        watch.undeclare()
    for cell, task in site.tasks.items():
        if task in done:
            raise AssertionError(f"the daemon of {cell} ended before serving: {task.exception()!r}")
    assert all_seen.is_set(), f"within {timeout} s the client saw only {sorted(seen)} of {sorted(robots)}"
    # The tokens reach a subscriber before a liveliness query through the router finds them (for a
    # few hundred ms after the daemons start): wait until the client's own discovery lists them too.
    deadline = loop.time() + timeout
    listed: list[str] = []
    for _ in range(DISCOVERY_TRIES):
        listed = [f"{cell}/{robot}" for cell, robot in await client.robots()]
        if robots <= set(listed) or loop.time() > deadline:
            break
        await asyncio.sleep(DISCOVERY_PAUSE_S)
    assert robots <= set(listed), f"the client's discovery lists only {listed} of {sorted(robots)}"


@asynccontextmanager
async def connected(endpoint: str) -> AsyncIterator[Client]:
    """A client of the router at ``endpoint``."""
    async with connected_with(endpoint, None) as client:
        yield client


@asynccontextmanager
async def connected_with(endpoint: str, config_file: Path | None) -> AsyncIterator[Client]:
    """A client of the router at ``endpoint``, its session started from ``config_file`` (TLS)."""
    config = None if config_file is None else str(config_file)
    client = await Client.connect(endpoint, timeout=10.0, config_file=config)
    try:
        yield client
    finally:
        await client.close()
