"""``urdaemon list``, ``info``, ``hz`` and ``echo``'s options against a mock cell in this loop.

Each command runs in-process in a thread of its own (``run_cli_in_thread``) so the daemon keeps
cycling in the test's loop. Rates are judged from the messages' own ``host_time_ns``, with wide
bands; nothing asserts on how long a command took.
"""

from __future__ import annotations

import itertools
import json
from collections.abc import AsyncIterator
from dataclasses import dataclass

import pytest

from tests.helpers import CliRun, acquire_lease, run_cli_in_thread
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon import __version__
from urdaemon.client import Client
from urdaemon.daemon import Daemon

pytestmark = pytest.mark.timeout(120)

CLI_TIMEOUT_S = 40.0


@dataclass(frozen=True)
class Served:
    daemon: Daemon
    client: Client
    endpoint: str
    cell: str


@pytest.fixture
async def served() -> AsyncIterator[Served]:
    """alice (UR10e, 500 Hz) and bob (UR5, 125 Hz) on the mock backend."""
    async with running_daemon(TWO_MOCKS) as (daemon, client):
        yield Served(daemon, client, daemon.listen_endpoints[0], daemon.cell.cell)


async def urdaemon(served: Served, *args: str) -> CliRun:
    return await run_cli_in_thread(*args, "--connect", served.endpoint, timeout=CLI_TIMEOUT_S)


def _row(text: str, robot: str) -> list[str]:
    rows = [line.split() for line in text.splitlines() if line.split()[:1] == [robot]]
    assert len(rows) == 1, text
    return rows[0]


async def test_list_shows_the_cell_its_daemon_and_every_robot_with_its_lease_holder(served: Served) -> None:
    grant = await acquire_lease(served.client.session, served.cell, "alice", holder="lister-test")
    try:
        run = await urdaemon(served, "list")
    finally:
        grant.liveliness.undeclare()
    assert run.code == 0, run.stderr
    assert f"cell {served.cell}: urdaemon {__version__}" in run.stdout
    assert served.endpoint in run.stdout
    assert _row(run.stdout, "alice") == ["alice", "mock", "ur10e", "500", "running", "lister-test"]
    assert _row(run.stdout, "bob") == ["bob", "mock", "ur5", "125", "running", "-"]


async def test_list_json_carries_what_the_daemon_answered(served: Served) -> None:
    run = await urdaemon(served, "list", "--json")
    assert run.code == 0, run.stderr
    data = json.loads(run.stdout)
    daemon = data["daemons"][served.cell]
    assert daemon["cell"] == served.cell
    assert daemon["listen"] == [served.endpoint]
    assert daemon["started_at_ns"] <= daemon["host_time_ns"]
    assert [r["name"] for r in daemon["robots"]] == ["alice", "bob"]
    alice = daemon["robots"][0]
    assert alice["publish_rates_hz"]["joint_states"] == 500.0
    assert f"{served.cell}/alice/joint_states" in alice["keys"]["published"]
    assert f"{served.cell}/alice/service/cycle_stats" in alice["keys"]["queryables"]
    assert sorted(data["alive"]) == [[served.cell, "alice"], [served.cell, "bob"]]


async def test_info_shows_the_robots_facts_and_measured_rates(served: Served) -> None:
    run = await urdaemon(served, "info", "alice", "--json")
    assert run.code == 0, run.stderr
    data = json.loads(run.stdout)
    robot = data["robot"]
    assert (data["cell"], robot["model"], robot["backend"]) == (served.cell, "ur10e", "mock")
    assert robot["controller_version"] is None  # the mock has no controller
    assert robot["ports"] is None
    assert robot["lease"] is None
    assert robot["joint_limits"]["names"][0] == "alice_shoulder_pan_joint"
    assert len(robot["joint_limits"]["max_velocity"]) == 6
    joints = data["measured"][f"{served.cell}/alice/joint_states"]
    assert joints["times"] == "host_time_ns"
    # one second of a 500 Hz stream; how much of it a loaded machine delivers is the machine's (79 Hz
    # measured beside two CPU burners): the rate comes from the daemon's stamps, never above the robot's
    assert joints["count"] >= 2
    assert 0 < joints["rate_hz"] <= 1000


async def test_info_text_names_every_section(served: Served) -> None:
    run = await urdaemon(served, "info", "bob", "--window", "0.5")
    assert run.code == 0, run.stderr
    for text in (
        "robot bob in cell testcell",
        "model:",
        "ur5",
        "controller:",
        "calibration:",
        "ports:",
        "tcp:",
        "lease:",
        "free",
        "joint limits:",
        "bob_elbow_joint",
        "keys:",
        "testcell/bob/joint_states",
        "125 Hz",
        "queryables (under testcell/bob/):",
        " lease,",
    ):
        assert text in run.stdout, text


async def test_info_of_an_unknown_robot_names_those_there_are(served: Served) -> None:
    run = await urdaemon(served, "info", "carol")
    assert run.code == 1
    assert "no robot 'carol'" in run.stderr
    assert "testcell/alice" in run.stderr
    assert "testcell/bob" in run.stderr


async def test_hz_reports_the_configured_rate_from_the_messages_own_times(served: Served) -> None:
    run = await urdaemon(served, "hz", f"{served.cell}/bob/joint_states", "--count", "60")
    assert run.code == 0, run.stderr
    assert "60 message(s) in" in run.stdout
    assert "(times: host_time_ns)" in run.stdout
    rates = [
        float(line.split(":")[1]) for line in run.stdout.splitlines() if line.startswith("average rate:")
    ]
    assert rates, run.stdout
    assert 60 <= rates[-1] <= 250  # 125 Hz configured; the band is wide, the source the daemon's clock
    assert "window: 60" in run.stdout


async def test_hz_of_a_key_nothing_publishes_names_what_there_is(served: Served) -> None:
    run = await urdaemon(served, "hz", f"{served.cell}/carol/joint_states")
    assert run.code == 1
    assert "no robot 'carol' in cell testcell; robots: alice, bob" in run.stderr


async def test_echo_field_picks_one_field(served: Served) -> None:
    run = await urdaemon(
        served, "echo", f"{served.cell}/alice/joint_states", "--field", "position.1", "--count", "2"
    )
    assert run.code == 0, run.stderr
    values = [json.loads(line)["value"] for line in run.stdout.splitlines()]
    assert values == [pytest.approx(-1.5708), pytest.approx(-1.5708)]


async def test_echo_field_that_is_missing_names_the_fields_there_are(served: Served) -> None:
    run = await urdaemon(served, "echo", f"{served.cell}/alice/joint_states", "--field", "positions")
    assert run.code == 2
    assert "no field 'positions' in the message" in run.stderr
    assert "position" in run.stderr
    assert "host_time_ns" in run.stderr


async def test_echo_rate_thins_a_500_hz_stream(served: Served) -> None:
    run = await urdaemon(
        served,
        "echo",
        f"{served.cell}/alice/joint_states",
        "--rate",
        "20",
        "--count",
        "6",
        "--field",
        "cycle",
    )
    assert run.code == 0, run.stderr
    cycles = [json.loads(line)["value"] for line in run.stdout.splitlines()]
    assert len(cycles) == 6
    steps = [b - a for a, b in itertools.pairwise(cycles)]
    # unthinned, each message is the next cycle; thinned to 20 Hz (by arrival: test_tables.py tests
    # thinning), cycles in between are left out. Counted, not timed: a loaded machine delivers the
    # stream in bursts, so the daemon's stamps of two passed messages may be closer than 50 ms.
    assert all(step >= 1 for step in steps), cycles
    assert sum(steps) > len(steps), cycles


async def test_echo_of_a_robot_that_does_not_exist_says_so_and_exits_1(served: Served) -> None:
    run = await urdaemon(served, "echo", f"{served.cell}/carol/joint_states")
    assert run.code == 1
    assert run.stdout == ""
    assert "warning:" in run.stderr
    assert "no robot 'carol' in cell testcell; robots: alice, bob" in run.stderr


async def test_echo_of_a_quiet_key_that_exists_keeps_waiting_until_its_timeout(served: Served) -> None:
    run = await urdaemon(served, "echo", f"{served.cell}/alice/events", "--timeout", "3.5")
    assert run.code == 1
    assert "note: nothing on testcell/alice/events" in run.stderr
    assert "still waiting" in run.stderr
    assert "error: no sample on testcell/alice/events within 3.5 s" in run.stderr


async def test_echo_with_a_timeout_keeps_waiting_for_a_robot_that_does_not_exist_yet(served: Served) -> None:
    run = await urdaemon(served, "echo", f"{served.cell}/carol/status", "--timeout", "3.5")
    assert run.code == 1
    assert "warning:" in run.stderr
    assert "no robot 'carol'" in run.stderr
    assert "within 3.5 s" in run.stderr


async def test_the_daemon_answers_its_key_once_and_no_robot_may_be_named_so(served: Served) -> None:
    from urdaemon.cell import parse_cell
    from urdaemon.errors import ConfigError

    replies = await served.client.query(f"{served.cell}/daemon")
    assert len(replies) == 1  # the cell-level queryable that names unknown robots stays silent
    answer = json.loads(replies[0])
    assert (answer["v"], answer["cell"]) == (1, served.cell)
    covering = await served.client.query_replies("**", timeout=2.0, every_queryable=True)
    assert [r.key for r in covering if r.key.endswith("/daemon")] == [f"{served.cell}/daemon"]
    with pytest.raises(ConfigError, match="daemon"):
        parse_cell(TWO_MOCKS.replace("name: bob", "name: daemon"))
