"""``urdaemon list`` over several cells: a daemon serving as a Zenoh router, another daemon joining
it as a peer, the command connected to the router only. Nothing assumes one cell."""

from __future__ import annotations

import json

import pytest

from tests.helpers import run_cli_in_thread
from tests.integration.conftest import running_daemon

pytestmark = pytest.mark.timeout(120)

NORTH = """
cell: north
zenoh: {mode: router}
robots:
  - {name: alice, model: ur5e, backend: mock}
"""


def _south(router: str) -> str:
    return f"""
cell: south
zenoh: {{connect: ["{router}"]}}
robots:
  - {{name: alice, model: ur10e, backend: mock}}
  - {{name: bob, model: ur3e, backend: mock}}
"""


async def test_list_and_info_cover_every_cell_the_router_reaches() -> None:
    async with running_daemon(NORTH) as (north, _):
        router = north.listen_endpoints[0]
        async with running_daemon(_south(router)):
            run = await run_cli_in_thread("list", "--json", "--connect", router, timeout=40)
            assert run.code == 0, run.stderr
            data = json.loads(run.stdout)
            assert sorted(data["daemons"]) == ["north", "south"]
            assert sorted(map(tuple, data["alive"])) == [
                ("north", "alice"),
                ("south", "alice"),
                ("south", "bob"),
            ]
            text = await run_cli_in_thread("list", "--connect", router, timeout=40)
            assert "cell north: urdaemon" in text.stdout
            assert "cell south: urdaemon" in text.stdout
            ambiguous = await run_cli_in_thread("info", "alice", "--connect", router, timeout=40)
            assert ambiguous.code == 1
            assert (
                "robot 'alice' is served in several cells (north, south); name one with --cell"
                in ambiguous.stderr
            )
            named = await run_cli_in_thread(
                "info", "alice", "--cell", "south", "--window", "0.3", "--connect", router, timeout=40
            )
            assert named.code == 0, named.stderr
            assert "robot alice in cell south" in named.stdout
            assert "ur10e" in named.stdout
