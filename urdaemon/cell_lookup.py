"""Which cell a client command follows, and its URDF, waited for a while: what ``urdaemon view`` and
``urdaemon foxglove`` ask first.

A session that has just connected (through a router, or to a daemon still starting) may hear of the
robots' liveliness tokens and the daemon's queryables a moment late, so both questions are asked
again every 0.1 s for at most ``wait_s``.
"""

from __future__ import annotations

import asyncio

from urdaemon.client import Client
from urdaemon.errors import UrDaemonError, UrTimeoutError

__all__ = ["WAIT_S", "cell_description", "served_cell"]

WAIT_S = 10.0
ASK_AGAIN_S = 0.1


async def served_cell(client: Client, cell: str | None, wait_s: float = WAIT_S) -> tuple[str, list[str]]:
    """The cell to follow (the one served, unless ``cell`` names it) and its robots, sorted; an error
    naming them when several cells are served and none is named, or none within ``wait_s``."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + wait_s
    while True:
        served = await client.robots()
        cells = sorted({c for c, _ in served if cell in (None, c)})
        if len(cells) == 1:
            return cells[0], sorted(r for c, r in served if c == cells[0])
        if len(cells) > 1:
            raise UrDaemonError(
                f"several cells are served at {client.endpoint} ({', '.join(cells)}); name one"
            )
        if loop.time() > deadline:
            named = f"cell {cell!r}" if cell is not None else "no robot"
            raise UrTimeoutError(f"{named} is not served at {client.endpoint} (waited {wait_s:g} s)")
        await asyncio.sleep(ASK_AGAIN_S)


async def cell_description(client: Client, cell: str, wait_s: float = WAIT_S) -> str:
    """The cell URDF, asked again while the daemon's queryable is not yet known, for at most
    ``wait_s``."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + wait_s
    while True:
        try:
            return await client.robot_description(cell)
        except UrTimeoutError:
            if loop.time() > deadline:
                raise
        await asyncio.sleep(ASK_AGAIN_S)
