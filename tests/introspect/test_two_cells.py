"""``urdaemon list`` over several cells: a daemon serving as a Zenoh router, another daemon joining
it as a peer, the command connected to the router only. Nothing assumes one cell."""

from __future__ import annotations

import json
from types import SimpleNamespace
from typing import Any, cast

import pytest

from tests.helpers import run_cli_in_thread
from tests.integration.conftest import running_daemon
from urdaemon.client import Client
from urdaemon.introspect.survey import ROUND_PAUSE_S, SURVEY_TIMEOUT_S, survey
from urdaemon.introspect.tables import list_lines

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


class _LateTokens:
    """A client whose daemon of cell ``south`` answers at once but whose robots' liveliness tokens
    arrive only after ``late`` answers (what a session behind a router sees on a busy machine), and
    then one at a time, a round apart."""

    endpoint = "tcp/127.0.0.1:7447"

    def __init__(self, late: int, tokens: list[tuple[str, str]]) -> None:
        self.late, self.tokens = late, tokens
        self.answers = 0

    async def robots(self, *, timeout: float) -> list[tuple[str, str]]:
        return self.tokens[: max(0, self.answers - self.late + 1)]

    async def query_replies(self, key: str, *, timeout: float, every_queryable: bool) -> list[Any]:
        assert key == "*/daemon"
        assert every_queryable
        self.answers += 1
        robots = [{"name": robot} for _, robot in self.tokens]
        return [SimpleNamespace(payload=json.dumps({"cell": "south", "robots": robots}).encode())]


async def test_the_listing_waits_for_the_tokens_of_every_robot_a_daemon_names() -> None:
    tokens = [("south", "alice"), ("south", "bob")]
    client = _LateTokens(late=2, tokens=tokens)
    found = await survey(cast(Client, client), timeout=SURVEY_TIMEOUT_S)
    assert found.alive == tokens
    assert sorted(found.daemons) == ["south"]
    assert found.untokened() == set()


async def test_a_token_that_never_comes_is_waited_for_only_until_the_timeout() -> None:
    client = _LateTokens(late=10**9, tokens=[("south", "alice")])
    found = await survey(cast(Client, client), timeout=0.3)
    assert found.alive == []
    assert found.untokened() == {("south", "alice")}
    assert 2 <= client.answers <= 2 + int(0.3 / ROUND_PAUSE_S)
    assert "no liveliness token" in "\n".join(list_lines(found))
