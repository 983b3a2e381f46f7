"""The cell's stop (``<cell>/service/stop``, ``urdaemon stop`` with no robot): every robot stops at once.

Issue 16 ("a cell-wide stop that stops every robot; ``urdaemon stop`` with no robot stops the cell").
Before it there was no such key: a query on it was answered by nobody, and stopping a cell meant one
stop per robot.
"""

from __future__ import annotations

import json

import pytest

from tests.helpers import run_cli_in_thread
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.cell.load import parse_cell
from urdaemon.errors import ConfigError
from urdaemon.publish.keys import CellKeys

pytestmark = pytest.mark.timeout(120)

TARGET = [0.3, -1.4, 1.4, -1.5, -1.6, 0.2]
LONG_MOVE_S = 30.0
"""Long enough that no move ends on its own while a test runs: only a stop ends it."""


async def test_the_cell_stop_stops_every_robot_and_ends_each_goal_once() -> None:
    async with running_daemon(TWO_MOCKS) as (daemon, client):
        alice = await client.robot("alice")
        bob = await client.robot("bob")
        goals = [await robot.move(TARGET, duration=LONG_MOVE_S) for robot in (alice, bob)]
        reply = await client.stop_cell()
        assert reply == {"v": 1, "ok": True, "robots": {"alice": {"ok": True}, "bob": {"ok": True}}}
        for goal in goals:
            result = await goal.result(timeout=10.0)
            assert result["status"] == "aborted"
            assert result["reason"] == "cell stop requested"
        for runtime in daemon.runtimes:
            assert runtime.controller.mode in ("stopping", "idle")


async def test_a_wildcard_on_the_cell_stop_key_stops_nothing() -> None:
    async with running_daemon(TWO_MOCKS) as (daemon, client):
        alice = await client.robot("alice")
        goal = await alice.move(TARGET, duration=LONG_MOVE_S)
        for wildcard in ("testcell/*/stop", "testcell/**"):
            await client.query(wildcard, timeout=2.0)  # refused with an error reply naming the key
        assert daemon.runtimes[0].controller.active_goal_id == goal.goal_id, "the goal still runs"
        await alice.cancel(goal.goal_id)


async def test_urdaemon_stop_without_a_robot_stops_the_cell_and_with_one_stops_that_robot() -> None:
    async with running_daemon(TWO_MOCKS) as (daemon, client):
        endpoint = daemon.listen_endpoints[0]
        alice = await client.robot("alice")
        bob = await client.robot("bob")
        alice_goal = await alice.move(TARGET, duration=LONG_MOVE_S)
        bob_goal = await bob.move(TARGET, duration=LONG_MOVE_S)
        one = await run_cli_in_thread("stop", "alice", "--connect", endpoint, timeout=30.0)
        assert one.code == 0, one.stderr
        assert (await alice_goal.result(timeout=10.0))["reason"] == "stop requested"
        assert daemon.runtimes[1].controller.active_goal_id == bob_goal.goal_id, "bob was not asked"
        whole = await run_cli_in_thread("stop", "--connect", endpoint, timeout=30.0)
        assert whole.code == 0, whole.stderr
        assert json.loads(whole.stdout)["robots"] == {"alice": {"ok": True}, "bob": {"ok": True}}
        assert (await bob_goal.result(timeout=10.0))["reason"] == "cell stop requested"
        bad = await run_cli_in_thread("stop", "--cell", "no/such", "--connect", endpoint, timeout=30.0)
        assert bad.code != 0
        assert "not a cell name" in bad.stderr


def test_a_robot_cannot_be_named_like_a_key_of_the_cell() -> None:
    """``<cell>/service/stop`` is the cell's: a robot named ``service`` would share its keys."""
    for name in ("service", "tf", "robot_description"):
        text = TWO_MOCKS.replace("name: bob", f"name: {name}")
        with pytest.raises(ConfigError, match=f"'{name}' names a key of the cell itself"):
            parse_cell(text)
    assert CellKeys("testcell").stop == "testcell/service/stop"
