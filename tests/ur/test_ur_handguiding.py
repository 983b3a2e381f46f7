"""Freedrive with its deadman, force mode and tool contact on the `ur` backend, against the fake."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from typing import Any

import pytest

from tests.helpers import fake_address, run_cli_in_thread
from tests.integration.conftest import running_daemon
from tests.ur.test_ur_backend import HOME, _cell, _until
from urdaemon.backends.ur.backend import UrBackend
from urdaemon.client import Client, RobotClient
from urdaemon.daemon import Daemon
from urdaemon.errors import GoalRejected
from urdaemon.fakeur.controller import FakeController

pytestmark = pytest.mark.timeout(90)


@contextlib.asynccontextmanager
async def _ready_alice() -> AsyncIterator[tuple[FakeController, Daemon, Client, RobotClient]]:
    """A fake UR10e at HOME and a daemon driving it as alice, once alice is ready; both closed after."""
    fake = FakeController("ur10e", address=fake_address(), initial_positions=HOME)
    await fake.start()
    try:
        async with running_daemon(_cell(fake.address)) as (daemon, client):
            alice = await client.robot("alice")
            await _until(client, alice.keys.status, lambda s: s["ready"])
            yield fake, daemon, client, alice
    finally:
        await fake.close()


def _freedrive(fake: FakeController) -> bool:
    """Read through a call: the type checker must not pin a flag the fake changes behind its back."""
    return fake.arm.freedrive


async def test_freedrive_holds_while_commanded_blocks_motion_and_the_deadman_ends_it() -> None:
    async with _ready_alice() as (fake, _, _, alice):
        states = alice.joint_states(10_000)
        await alice.ensure_lease()  # stream commands need the lease held first; they never wait for it
        for _ in range(40):  # 0.4 s of commands, one every 5 cycles (10 ms) at 500 Hz
            alice.freedrive(True)
            for _ in range(5):
                await states.get(timeout=5.0)
        assert fake.arm.freedrive is True
        with pytest.raises(GoalRejected, match="freedrive is on"):
            await alice.move(HOME, duration=1.0)
        # no more commands: the deadman (stream_timeout 0.2 s) ends freedrive
        for _ in range(1000):
            await states.get(timeout=5.0)
            if not _freedrive(fake):
                break
        assert _freedrive(fake) is False
        goal = await alice.move([0.1, *HOME[1:]], duration=1.0)
        assert (await goal.result(timeout=20))["status"] == "succeeded"


async def test_force_mode_and_tool_contact_reach_the_robot() -> None:
    async with _ready_alice() as (fake, _, client, alice):
        events = client.subscribe(alice.keys.events, 100)
        reply = await alice.start_force_mode(
            [0.0] * 6, [0, 0, 1, 0, 0, 0], [0.0, 0.0, -10.0, 0.0, 0.0, 0.0], [0.1] * 6
        )
        assert reply["ok"] is True
        await _until(client, alice.keys.joint_states, lambda m: fake.arm.force_mode, limit=2000)
        assert fake.arm.force_mode is True
        token = (await alice.ensure_lease()).encode()  # refused for its selection, not for the lease
        bad = await alice.client.request(
            alice.keys.service("start_force_mode"), {"selection": [2] * 6}, attachment=token
        )
        assert bad["ok"] is False
        assert bad["reason"].startswith("start_force_mode"), bad
        assert (await alice.end_force_mode())["ok"] is True
        await _until(client, alice.keys.joint_states, lambda m: not fake.arm.force_mode, limit=2000)
        assert (await alice.start_tool_contact())["ok"] is True
        assert (await alice.end_tool_contact())["ok"] is True
        event: dict[str, Any] = {}
        for _ in range(50):
            event = await events.get_json(timeout=10.0)
            if event["kind"] == "tool_contact":
                break
        assert event["kind"] == "tool_contact"
        assert event["text"] == "canceled", "nothing around the fake arm to touch: ending it cancels"


async def test_freedrive_and_force_mode_on_a_mock_robot_are_refused_with_reasons() -> None:
    async with running_daemon("cell: m\nrobots:\n  - {name: alice, model: ur10e, backend: mock}\n") as (
        _,
        client,
    ):
        alice = await client.robot("alice")
        await alice.ensure_lease()  # stream commands need the lease held first; they never wait for it
        events = client.subscribe(alice.keys.events, 10)  # from here on: no lease event to skip
        alice.freedrive(True)
        event = await events.get_json(timeout=10.0)
        assert event["kind"] == "command_rejected"
        assert "no freedrive" in event["reason"]
        reply = await alice.start_force_mode([0.0] * 6, [0] * 6, [0.0] * 6, [0.1] * 6)
        assert reply["ok"] is False
        assert "no force mode" in reply["reason"]


async def test_hand_back_control_ends_the_program_until_it_is_resent_and_a_lost_link_shows_recovering() -> (
    None
):
    async with _ready_alice() as (fake, daemon, client, alice):
        backend = daemon.runtimes[0].backend
        statuses = client.subscribe(alice.keys.status, 1000)
        assert (await alice.hand_back_control())["ok"] is True
        # wait for the status that says why (a busy machine may publish one before the reason is known)
        handed = await _until(
            client, alice.keys.status, lambda s: not s["program_running"] and "handed back" in s["reason"]
        )
        assert handed["reason"].startswith("control handed back to the robot"), handed
        # the program is not sent again by itself: 3 s of status (past the 2 s resend window)
        states = alice.joint_states(10_000)
        for _ in range(1500):
            await states.get(timeout=5.0)
        assert not backend.servers.reverse.connected  # type: ignore[attr-defined]
        assert (await alice.resend_program())["ok"] is True
        await _until(client, alice.keys.status, lambda s: s["ready"])
        # a lost link: the robot shows recovering, then ready again
        fake.drop("rtde")
        seen = []
        for _ in range(100):
            status = await statuses.get_json(timeout=10.0)
            seen.append(status["lifecycle"])
            if "recovering" in seen and status["ready"]:
                break
        assert "recovering" in seen, seen
        goal = await alice.move([0.1, *HOME[1:]], duration=1.0)
        assert (await goal.result(timeout=20))["status"] == "succeeded"


async def test_position_streaming_drives_the_ur_robot_and_the_cli_calls_services() -> None:
    import json

    async with _ready_alice() as (fake, daemon, client, alice):
        states = alice.joint_states(10_000)
        target = [0.15, *HOME[1:]]
        await alice.ensure_lease()  # stream commands need the lease held first; they never wait for it
        for _ in range(60):  # 0.6 s of streaming, one command every 5 cycles
            alice.stream_positions(target)
            for _ in range(5):
                await states.get(timeout=5.0)
        assert fake.arm.q[0] == pytest.approx(0.15, abs=0.005), "servoj streaming reached the target"
        for _ in range(1000):  # the deadman stops the stream; the arm rests
            sample = await states.get_json(timeout=5.0)
            if all(v == 0.0 for v in sample["velocity"]) and daemon.runtimes[0].controller.mode == "idle":
                break
        assert daemon.runtimes[0].controller.mode == "idle"
        await alice.release()  # the CLI below is another client: it takes the lease for each call

        async def cli(*args: str) -> tuple[int, str]:
            """``urdaemon service alice ARGS`` in-process (in a thread; the daemon keeps serving)."""
            run = await run_cli_in_thread(
                "service", "alice", *args, "--connect", daemon.listen_endpoints[0], timeout=60.0
            )
            return run.code, run.stdout + run.stderr

        code, out = await cli("set_io", json.dumps({"kind": "digital", "pin": 6, "value": True}))
        assert code == 0, out
        assert json.loads(out.splitlines()[0])["ok"] is True
        await _until(client, alice.keys.io, lambda m: m["digital_out"][6])
        assert fake.arm.io.digital_out & (1 << 6)
        code, out = await cli("set_tool_voltage", json.dumps({"volts": 7}))
        assert code == 1
        assert "0, 12 or 24" in out
        code, out = await cli("set_io", "not json")
        assert code == 2
        assert "not JSON" in out


async def test_missed_rtde_packages_are_counted_from_the_controllers_clock() -> None:
    async with _ready_alice() as (fake, daemon, client, alice):
        before = daemon.runtimes[0].backend.statistics().missed_cycles
        fake.stall(0.1)  # 50 packages at 500 Hz never sent
        status = await _until(client, alice.keys.status, lambda s: s["missed_cycles"] >= before + 45)
        assert status["missed_cycles"] - before <= 55
        assert status["late_cycles"] >= 1


async def test_packages_queued_while_the_loop_was_held_up_count_late_not_missed_the_goal_goes_on() -> None:
    """Packages that queue while the loop is held up all run the controller, late, and none is missed.

    Every count compared is taken over the same window (from just before the hold-up to the goal's end):
    the RTDE link's ``superseded`` is a count since the link opened, and on a busy machine packages also
    queue up during start-up, so comparing it whole with the window's late cycles failed 3/3 under load.
    """
    async with _ready_alice() as (fake, daemon, _, alice):
        backend = daemon.runtimes[0].backend
        assert isinstance(backend, UrBackend)
        rtde = backend.links.rtde
        assert rtde is not None
        assert rtde.transport is not None
        goal = await alice.move([0.2, *HOME[1:]], duration=1.0)
        # one synchronous snapshot: no cycle can run between these reads
        before, turnarounds, superseded = backend.statistics(), backend.turnaround.count, rtde.superseded
        rtde.transport.pause_reading()  # as if the loop were held up for 10 controller cycles
        await fake.cycles_pass(10)  # raises if the fake does not run 10 cycles (30 s bound)
        rtde.transport.resume_reading()
        result = await goal.result(timeout=20)
        assert result["status"] == "succeeded"
        assert max(abs(e) for e in result["final_error"]) < 1e-3
        after, turnarounds_after, superseded_after = (
            backend.statistics(),
            backend.turnaround.count,
            rtde.superseded,
        )
        window_superseded = superseded_after - superseded
        assert window_superseded >= 9, (
            "the queued packages arrived in one read, all but the newest superseded"
        )
        assert after.late_cycles - before.late_cycles >= window_superseded
        assert after.missed_cycles == before.missed_cycles, "they arrived: none was missed"
        assert after.cycles - before.cycles == turnarounds_after - turnarounds + window_superseded, (
            "every package ran the controller; a command went out for all but the superseded ones"
        )
