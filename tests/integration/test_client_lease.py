"""The client side of the command lease (issue 16): two clients of one daemon, the CLI in-process.

Reproduction on the code before the lease: a second client's move, trajectory, service call and
stream went through while the first client's goal ran (the move was refused only as ``busy``, the
service and the stream not at all), nothing could take a robot over, and ``urdaemon lease`` did not
exist.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import pytest

from tests.helpers import run_cli_in_thread
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.client import Client, GoalHandle, LeaseHeld, RobotClient
from urdaemon.daemon import Daemon
from urdaemon.errors import UrDaemonError

pytestmark = pytest.mark.timeout(120)

HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
AWAY = [0.2, -1.4, 1.4, -1.5, -1.6, 0.1]
FIRST = "first client (test)"
SECOND = "second client (test)"
CLI_S = 30.0


@asynccontextmanager
async def two_clients() -> AsyncIterator[tuple[Daemon, Client, Client]]:
    """The two-mock cell, and two clients of it that name themselves FIRST and SECOND."""
    async with running_daemon(TWO_MOCKS) as (daemon, _):
        endpoint = daemon.listen_endpoints[0]
        first = await Client.connect(endpoint, holder=FIRST)
        async with first, await Client.connect(endpoint, holder=SECOND) as second:
            yield daemon, first, second


async def _long_goal(robot: RobotClient) -> GoalHandle:
    """A goal that runs far longer than any test (it ends by a stop, a take-over or a release)."""
    return await robot.move(AWAY, duration=60.0)


async def test_a_second_clients_commands_are_refused_naming_the_holder_and_stop_always_works() -> None:
    async with two_clients() as (daemon, first, second):
        mine, theirs = await first.robot("alice"), await second.robot("alice")
        goal = await _long_goal(mine)
        assert len(mine.lease.token or "") == 32
        refused = [
            theirs.move(HOME, duration=2.0, preempt=True),
            theirs.send_trajectory([{"positions": HOME, "time_from_start": 2.0}], preempt=True),
            theirs.set_io("digital", 3, True),
            theirs.dashboard("power off"),
            theirs.cancel(goal.goal_id),
            theirs.ensure_lease(),
        ]
        for call in refused:
            with pytest.raises(LeaseHeld) as caught:
                await call
            assert caught.value.reason.startswith("lease: "), caught.value.reason
            assert FIRST in caught.value.reason, caught.value.reason
        with pytest.raises(LeaseHeld, match="held by first client"):  # as last refused: no waiting
            theirs.stream_velocities([0.1] * 6)
        other = await second.robot("bob")  # never asked for bob's lease: a stream says what to do
        with pytest.raises(UrDaemonError, match="ensure_lease"):
            other.stream_positions(HOME)
        assert daemon.runtimes[0].controller.active_goal_id == goal.goal_id, "the first's goal runs on"
        assert (await theirs.cycle_stats())["ok"] is True  # reading counters needs no lease
        assert (await theirs.stop())["ok"] is True  # stop: anyone, always
        assert (await goal.result(timeout=10.0))["status"] == "aborted"
        assert theirs.lease.token is None, "stop never acquires the lease"
        info = await theirs.lease_info()
        assert info is not None
        assert info["holder"] == FIRST


async def test_after_the_holder_closes_the_second_client_commands() -> None:
    async with running_daemon(TWO_MOCKS) as (daemon, _):
        endpoint = daemon.listen_endpoints[0]
        async with await Client.connect(endpoint, holder=SECOND) as second:
            theirs = await second.robot("alice")
            async with await Client.connect(endpoint, holder=FIRST) as first:
                mine = await first.robot("alice")
                await mine.ensure_lease()
                with pytest.raises(LeaseHeld, match="first client"):
                    await theirs.move(AWAY, duration=1.0)
            # the first client closed: it released its lease
            assert await theirs.lease_info() is None
            goal = await theirs.move(AWAY, duration=1.0)
            assert (await goal.result(timeout=30.0))["status"] == "succeeded"
            positions = daemon.runtimes[0].backend.state.positions
            assert list(positions) == pytest.approx(AWAY, abs=0.01)
            await theirs.ensure_lease()  # streams need the lease held first; then they go through
            states = theirs.joint_states(10_000)
            before = daemon.runtimes[0].backend.state.positions[0]
            for _ in range(30):
                theirs.stream_velocities([0.2, 0.0, 0.0, 0.0, 0.0, 0.0])
                for _ in range(5):
                    await states.get(timeout=5.0)
            assert daemon.runtimes[0].backend.state.positions[0] > before + 0.01, "the stream moved alice"


async def test_take_over_passes_the_lease_and_the_first_clients_next_command_is_refused() -> None:
    async with two_clients() as (_, first, second):
        mine, theirs = await first.robot("alice"), await second.robot("alice")
        goal = await _long_goal(mine)
        reply = await theirs.take_over("the operator needs alice")
        assert reply["ok"] is True
        assert reply["lease"]["holder"] == SECOND
        assert (await goal.result(timeout=10.0))["status"] == "aborted", "taking over stops the robot"
        await asyncio.wait_for(mine.lease.ended.wait(), 10.0)  # the take-over event reached the first
        taken = r"taken over by second client \(test\): the operator needs alice"
        with pytest.raises(LeaseHeld, match=taken):
            mine.stream_velocities([0.1] * 6)  # said at once, not published to be refused
        with pytest.raises(LeaseHeld) as caught:
            await mine.move(HOME, duration=2.0)
        assert SECOND in caught.value.reason, caught.value.reason
        moved = await theirs.move(HOME, duration=1.0)
        assert (await moved.result(timeout=30.0))["status"] == "succeeded"
        with pytest.raises(UrDaemonError, match="reason"):
            await mine.take_over("  ")


async def test_cancel_from_another_process_is_refused_naming_the_holder() -> None:
    """``urdaemon cancel``/``move`` from another terminal while a program holds the lease: refused
    with the daemon's reason, exit 1 (as every refusal); ``urdaemon stop`` still stops the robot."""
    async with two_clients() as (daemon, first, _):
        endpoint = daemon.listen_endpoints[0]
        goal = await _long_goal(await first.robot("alice"))
        cancel = await run_cli_in_thread("cancel", "alice", "--connect", endpoint, timeout=CLI_S)
        assert cancel.code == 1, cancel
        assert "lease: robot 'alice' is held by first client (test)" in cancel.stderr, cancel
        move = await run_cli_in_thread(
            "move", "alice", "--joints", "0,-1.5708,1.5708,-1.5708,-1.5708,0", "--connect", endpoint,
            timeout=CLI_S,
        )  # fmt: skip
        assert move.code == 1, move
        assert "rejected: lease: robot 'alice' is held by first client (test)" in move.stderr, move
        assert daemon.runtimes[0].controller.active_goal_id == goal.goal_id
        stop = await run_cli_in_thread("stop", "alice", "--connect", endpoint, timeout=CLI_S)
        assert stop.code == 0, stop
        assert (await goal.result(timeout=10.0))["status"] == "aborted"


async def test_lease_command_shows_the_holder_and_takes_it_over() -> None:
    async with two_clients() as (daemon, first, _):
        endpoint = daemon.listen_endpoints[0]
        free = await run_cli_in_thread("lease", "alice", "--connect", endpoint, timeout=CLI_S)
        assert (free.code, free.stdout.strip()) == (0, "alice: free"), free
        mine = await first.robot("alice")
        goal = await _long_goal(mine)
        shown = await run_cli_in_thread("lease", "alice", "--connect", endpoint, timeout=CLI_S)
        assert shown.code == 0, shown
        assert f"alice: held by {FIRST} since " in shown.stdout, shown
        assert f"(session {first.session.zid()})" in shown.stdout, shown
        taken = await run_cli_in_thread(
            "lease", "alice", "--take-over", "stuck client", "--connect", endpoint, timeout=CLI_S
        )
        assert taken.code == 0, taken
        assert f"took over alice's lease from {FIRST}" in taken.stdout, taken
        assert "released" in taken.stdout, taken
        assert (await goal.result(timeout=10.0))["status"] == "aborted"
        assert await mine.lease_info() is None, "the take-over was released when the command ended"
        for _ in range(2):  # the lease is free, but a client it was taken from does not just take it back
            with pytest.raises(LeaseHeld, match="lease: robot 'alice'"):
                await mine.move(HOME, duration=1.0)
        assert await mine.lease_info() is None
        await mine.ensure_lease()  # the program decides to command again
        again = await mine.move(HOME, duration=1.0)
        assert (await again.result(timeout=30.0))["status"] == "succeeded"


async def test_lease_take_over_without_a_reason_is_a_bad_argument() -> None:
    run = await run_cli_in_thread(
        "lease", "alice", "--take-over", " ", "--connect", "tcp/127.0.0.1:9", timeout=CLI_S
    )
    assert run.code == 2, run
    assert "--take-over needs a reason" in run.stderr


async def test_close_releases_the_lease_and_the_release_stops_a_goal_still_running() -> None:
    async with running_daemon(TWO_MOCKS) as (daemon, watcher):
        endpoint = daemon.listen_endpoints[0]
        first = await Client.connect(endpoint, holder=FIRST)
        try:
            goal = await _long_goal(await first.robot("alice"))
            alice = await watcher.robot("alice")
            results = watcher.subscribe(alice.keys.goal_result(goal.goal_id), 10)
        finally:
            await first.close()
        assert await alice.lease_info() is None
        result = await results.get_json(timeout=10.0)
        assert result["status"] == "aborted", result
        assert "released by first client (test)" in result["reason"], result
