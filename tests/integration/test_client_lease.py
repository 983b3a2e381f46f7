"""The client side of the command lease (issue 16): two clients of one daemon, the CLI in-process.

Reproduction on the code before the lease: a second client's move, trajectory, service call and
stream went through while the first client's goal ran (the move was refused only as ``busy``, the
service and the stream not at all), nothing could take a robot over, and ``urdaemon lease`` did not
exist.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import pytest
import zenoh

from tests.helpers import run_cli_in_thread
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.client import Client, GoalHandle, Lease, LeaseHeld, RobotClient
from urdaemon.daemon import Daemon
from urdaemon.errors import UrDaemonError, UrTimeoutError
from urdaemon.publish.session_config import zenoh_config

pytestmark = pytest.mark.timeout(120)

HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
AWAY = [0.2, -1.4, 1.4, -1.5, -1.6, 0.1]
FIRST = "first client (test)"
SECOND = "second client (test)"
CLI_S = 30.0
SHORT_S = 0.6
"""A move that must go through and end: its length is not the point (the mock needs 0.53 s for 0.2 rad)."""
WAIT_S = 20.0
"""Bound of every wait for a message (a busy machine is slow, never this slow)."""
ROUTED_TRIES = 100
"""Publications of a forged event until the client is seen to receive and weigh it; each waits at
most 0.1 s for the client's session to receive it."""


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
            theirs.ensure_lease(),
        ]
        for call in refused:
            with pytest.raises(LeaseHeld) as caught:
                await call
            assert caught.value.reason.startswith("lease: "), caught.value.reason
            assert FIRST in caught.value.reason, caught.value.reason
            assert "`urdaemon lease alice --take-over REASON`" in caught.value.reason  # the way out
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
                    await theirs.move(AWAY, duration=SHORT_S)
            # the first client closed: it released its lease
            assert await theirs.lease_info() is None
            goal = await theirs.move(AWAY, duration=SHORT_S)
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
        moved = await theirs.move(HOME, duration=SHORT_S)
        assert (await moved.result(timeout=30.0))["status"] == "succeeded"
        with pytest.raises(UrDaemonError, match="reason"):
            await mine.take_over("  ")


async def test_cancel_from_another_process_cancels_the_holders_goal() -> None:
    """``urdaemon cancel`` from another terminal while a program holds the lease cancels its goal (a
    cancel only stops the robot: issue 32; before, it was refused naming the holder); ``move`` from
    there is refused with the daemon's reason naming the CLI's ways out, exit 1; ``urdaemon stop``
    stops the robot."""
    async with two_clients() as (daemon, first, _):
        endpoint = daemon.listen_endpoints[0]
        mine = await first.robot("alice")
        goal = await _long_goal(mine)
        move = await run_cli_in_thread(
            "move", "alice", "--joints", "0,-1.5708,1.5708,-1.5708,-1.5708,0", "--connect", endpoint,
            timeout=CLI_S,
        )  # fmt: skip
        assert move.code == 1, move
        assert "rejected: lease: robot 'alice' is held by first client (test)" in move.stderr, move
        assert "`urdaemon stop alice`" in move.stderr, move
        assert "`urdaemon lease alice --take-over REASON`" in move.stderr, move
        assert daemon.runtimes[0].controller.active_goal_id == goal.goal_id
        cancel = await run_cli_in_thread("cancel", "alice", "--connect", endpoint, timeout=CLI_S)
        assert cancel.code == 0, cancel
        assert '"canceled": true' in cancel.stdout, cancel
        assert (await goal.result(timeout=10.0))["status"] == "canceled"
        assert mine.lease.token is not None, "the holder keeps its lease"
        second = await _long_goal(mine)
        stop = await run_cli_in_thread("stop", "alice", "--connect", endpoint, timeout=CLI_S)
        assert stop.code == 0, stop
        assert (await second.result(timeout=10.0))["status"] == "aborted"


async def test_lease_command_shows_the_holder_and_takes_it_over() -> None:
    """``urdaemon lease`` shows the holder's fingerprint, never its session id (contract 16b, decision
    1). Reproduction on 94dec3a: it printed ``(session <zid>)``, the id anyone could acquire with to
    get the holder's token."""
    async with two_clients() as (daemon, first, _):
        endpoint = daemon.listen_endpoints[0]
        free = await run_cli_in_thread("lease", "alice", "--connect", endpoint, timeout=CLI_S)
        assert (free.code, free.stdout.strip()) == (0, "alice: free"), free
        mine = await first.robot("alice")
        goal = await _long_goal(mine)
        shown = await run_cli_in_thread("lease", "alice", "--connect", endpoint, timeout=CLI_S)
        assert shown.code == 0, shown
        assert f"alice: held by {FIRST} since " in shown.stdout, shown
        assert "(fingerprint " in shown.stdout, shown
        assert "session" not in shown.stdout, shown
        assert f"(fingerprint {mine.lease.fingerprint})" in shown.stdout, shown
        assert mine.lease._session not in shown.stdout, "the secret session id is never shown"
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
                await mine.move(HOME, duration=SHORT_S)
        assert await mine.lease_info() is None
        await mine.ensure_lease()  # the program decides to command again
        again = await mine.move(HOME, duration=SHORT_S)
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


@asynccontextmanager
async def forger(endpoint: str) -> AsyncIterator[Any]:
    """A bare Zenoh session (no urdaemon code) connected to the daemon in Zenoh's client mode."""
    loop = asyncio.get_running_loop()
    session = await loop.run_in_executor(None, zenoh.open, zenoh_config("client", [], [endpoint]))
    try:
        yield session
    finally:
        await loop.run_in_executor(None, session.close)


async def _forge_until_weighed(client: Client, raw: Any, lease: Lease, key: str, payload: bytes) -> None:
    """Publish ``payload`` on ``key`` from ``raw`` until ``client``'s session received it and the
    lease has weighed it: its check of the event ran (or, in a client without checks, it ended)."""
    watch = client.subscribe(key, 1000)
    try:
        for _ in range(ROUTED_TRIES):
            raw.put(key, payload)
            try:
                while (await watch.get(timeout=0.1))[1] != payload:
                    pass
            except UrTimeoutError:
                continue
            checking = getattr(lease, "checking", None)
            if checking is not None:
                await asyncio.wait_for(checking, WAIT_S)
            if lease.ended.is_set() or getattr(lease, "checks", 0) > 0:
                return
        raise AssertionError(f"the forged event on {key} was never weighed by the client")
    finally:
        client.unsubscribe(watch)


async def test_a_forged_take_over_event_does_not_end_the_holders_lease() -> None:
    """M4 (contract 16b, decision 5): the client ends its lease on a lease event only once ``show``
    says it is no longer its own. Reproduction on 94dec3a: a raw session published on
    ``testcell/alice/events`` a ``taken_over`` event naming the holder's lease (as ``show`` gives it)
    as the previous one; the client dropped its lease at once (its next goal raised ``LeaseHeld``)
    and undeclared its token, so the daemon freed the lease and stopped alice."""
    async with two_clients() as (daemon, first, _), forger(daemon.listen_endpoints[0]) as raw:
        mine = await first.robot("alice")
        await mine.ensure_lease()
        shown = await mine.lease_info()
        assert shown is not None
        event = {
            "kind": "lease",
            "action": "taken_over",
            "holder": "nobody",
            "fingerprint": "0" * 16,
            "session": "forged",
            "previous": shown,
            "reason": "forged",
        }
        await _forge_until_weighed(first, raw, mine.lease, mine.keys.events, json.dumps(event).encode())
        assert not mine.lease.ended.is_set(), mine.lease.ended_reason
        assert mine.lease.token is not None
        goal = await mine.move(AWAY, duration=SHORT_S)
        assert (await goal.result(timeout=30.0))["status"] == "succeeded"
        after = await mine.lease_info()
        assert after is not None
        assert after["fingerprint"] == mine.lease.fingerprint, after
        assert after["since"] == shown["since"], "the daemon never saw the lease end"
        assert mine.lease.checks >= 1, "the forged event was never checked with the daemon"


async def test_a_lost_lease_is_noticed_by_streams() -> None:
    """Contract 16b, decision 5: streams notice a lease that ended by any of taken_over, lost and
    released. Reproduction on 94dec3a: only a take-over was noticed; after the lease was lost (the
    holder's liveliness token gone while its session stays, as when a network cut drops it) the
    client kept publishing stream commands the daemon refused, raising nothing."""
    async with two_clients() as (daemon, first, _):
        mine = await first.robot("alice")
        await mine.ensure_lease()
        mine.stream_velocities([0.0] * 6)
        mine.lease._undeclare()  # the token goes; the daemon ends the lease as lost and says so
        await asyncio.wait_for(mine.lease.ended.wait(), WAIT_S)
        with pytest.raises(LeaseHeld, match=r"no longer this client's \(lease holder first client"):
            mine.stream_velocities([0.1] * 6)
        assert await mine.lease_info() is None
        assert daemon.runtimes[0].lease.book.lease is None


async def test_a_refusal_for_the_lease_ends_it_only_when_the_daemon_shows_it_is_not_ours() -> None:
    """A command's answer refusing it for the lease could come from another session answering the
    command's query: the client ends its lease only once ``show`` agrees (as for events, decision 5).
    Before, any such answer ended the lease at once."""
    async with two_clients() as (_, first, second):
        mine, theirs = await first.robot("alice"), await second.robot("alice")
        await mine.ensure_lease()
        await mine.lease.confirm_end("lease: robot 'alice' is held by a forger")
        assert not mine.lease.ended.is_set(), mine.lease.ended_reason
        assert mine.lease.token is not None
        await theirs.take_over("the operator needs alice")
        await mine.lease.confirm_end("lease: robot 'alice' is held by second client (test)")
        assert mine.lease.ended.is_set()  # by this check, or by the take-over event if it came first
        with pytest.raises(LeaseHeld, match="second client"):
            await mine.move(HOME, duration=SHORT_S)
