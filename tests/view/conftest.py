"""Fixtures: the demo cell (configs/dual_robot_mock.yaml's robots on the mock backend) served in the
test's loop, and ``urdaemon view`` running against it on a port the OS chose."""

from __future__ import annotations

import math
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass

import pytest

from tests.integration.conftest import ROOT, running_daemon
from urdaemon.client import Client
from urdaemon.daemon import Daemon
from urdaemon.view.app import View, running_view

DEMO_CELL = (ROOT / "configs" / "dual_robot_mock.yaml").read_text(encoding="utf-8")
"""The demo cell; ``running_daemon`` listens on a free port of its own instead of the file's."""
DRAWS = 300
"""At most this many display updates (~10 s at 30 Hz) for anything a test waits on."""
DRAW_TIMEOUT_S = 10.0
"""...each of which must come within this long."""


@dataclass
class Viewed:
    daemon: Daemon
    client: Client
    view: View

    async def until(self, what: str, check: Callable[[], bool], draws: int = DRAWS) -> None:
        """Wait, one display update at a time (at most ``draws``), until ``check()`` holds."""
        for _ in range(draws):
            if check():
                return
            await self.view.drawn(DRAW_TIMEOUT_S)
        raise AssertionError(f"{what}: not within {draws} display updates")


@pytest.fixture
async def viewed() -> AsyncIterator[Viewed]:
    async with running_daemon(DEMO_CELL) as (daemon, client), running_view(client, port=0) as view:
        yield Viewed(daemon, client, view)


def close(a: tuple[float, ...], b: tuple[float, ...], tol: float) -> bool:
    return len(a) == len(b) and all(math.isclose(x, y, abs_tol=tol) for x, y in zip(a, b, strict=True))


async def tf_links(client: Client) -> dict[str, list[float]]:
    """The daemon's newest ``demo_cell/tf``: each link's world pose (x, y, z, qx, qy, qz, qw)."""
    sub = client.subscribe("demo_cell/tf", maxsize=10)
    try:
        links: dict[str, list[float]] = (await sub.get_json(10.0))["links"]
        return links
    finally:
        client.unsubscribe(sub)
