"""Issue 32: a flood of wildcard queries reached the other robot.

`get("**")` in a loop on the `ur` cell made 11-14 % of cycles late, and flooding only
`<cell>/alice/**` made bob late: Zenoh calls every queryable a wildcard intersects (~50 for `**` on
two robots), and each built and sent an error reply on Zenoh's thread, holding the GIL every robot's
cycle needs, while `<cell>/daemon` built its description on the loop for each one; the flooder got
its answers at once and asked again. Now the node's Python work for wildcard queries is bounded per
second, whichever keys are flooded, and a query past the bound is held unanswered (the flooder
waits). benchmarks/query_flood.py measures the late cycles (docs/performance.md).

Counted on a frozen budget clock: however many wildcard queries arrive, the error replies built and
the queries handed to the loop stay within the budgets.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import AsyncIterator
from typing import Any

import pytest
import zenoh

from tests.helpers import load_benchmark
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.client import Client
from urdaemon.daemon import Daemon
from urdaemon.publish import admission
from urdaemon.publish import node as node_module
from urdaemon.publish.admission import CELL_QUERIES_PER_S

pytestmark = pytest.mark.timeout(120)

FLOOD = 100
"""Wildcard queries sent at once after the first (each reaching every queryable it covers)."""


@pytest.fixture
async def cell() -> AsyncIterator[tuple[Daemon, Client]]:
    async with running_daemon(TWO_MOCKS) as pair:
        yield pair


def _get(client: Client, key: str, count: int) -> int:
    """Send ``count`` gets of ``key`` at once and wait until each ended (a held one times out); the
    replies received."""
    lock = threading.Lock()
    replies = [0]
    ended = threading.Semaphore(0)

    def on_reply(_reply: Any) -> None:
        with lock:
            replies[0] += 1

    for _ in range(count):
        client.session.get(key, zenoh.handlers.Callback(on_reply, ended.release), timeout=1.0)
    for _ in range(count):
        assert ended.acquire(timeout=30.0), "a query never ended"
    return replies[0]


@pytest.mark.parametrize("key", ["**", "testcell/alice/**"])
async def test_a_wildcard_flood_costs_a_bounded_number_of_replies_and_loop_calls(
    cell: tuple[Daemon, Client], monkeypatch: pytest.MonkeyPatch, key: str
) -> None:
    daemon, client = cell
    await client.robot("alice")
    node = daemon.node
    assert node is not None
    frozen = node.wildcards.clock()
    node.wildcards.clock = lambda: frozen  # no refill while the test runs: counts, not rates
    for budget in node.cell_queries.values():
        budget.clock = lambda: frozen
    node.tarpit.hold_s = 0.0  # a held query ends when the next is held (the holding: test_admission_budget)
    refusals: list[str] = []
    original = admission.refuse_query

    def counted(query: Any, reason: str, **kwargs: Any) -> None:
        refusals.append(reason)
        original(query, reason, **kwargs)

    monkeypatch.setattr(node_module, "refuse_query", counted)
    assert await asyncio.to_thread(_get, client, key, 1) > 0  # one query is answered whole
    one = len(refusals)
    assert one >= 20  # every service and goal key of alice (and of bob, for **) refuses it
    unknown_robots = node.cell_queries["testcell/*/**"]
    dropped_before = unknown_robots.dropped

    await asyncio.to_thread(_get, client, key, FLOOD)

    # before: FLOOD x one refusals built on Zenoh's threads (4800 for **); now at most the burst
    assert len(refusals) <= node.wildcards.burst < FLOOD * one
    assert node.wildcards.dropped >= FLOOD * one - node.wildcards.burst
    # the loop-side answerer of unknown robots, covered by both, took at most its budget
    assert unknown_robots.dropped - dropped_before >= FLOOD + 1 - CELL_QUERIES_PER_S
    # and the robots answer their exact keys at once
    stats = await (await client.robot("bob")).call("cycle_stats")
    assert stats["ok"] is True


async def test_the_benchmark_stays_runnable() -> None:
    """benchmarks/query_flood.py: a tiny run of no flood and a flood of alice's keys counts cycles."""
    bench = load_benchmark("query_flood")
    rows = await bench.measure(0.5, ("", "flood/alice/**"))
    assert [row["key"] for row in rows] == ["(none)", "flood/alice/**"]
    assert rows[1]["queries"] >= 1
    assert all(row["alice"][0] > 0 and row["bob"][0] > 0 for row in rows)
