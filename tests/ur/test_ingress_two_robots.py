"""Issue 13, finding 2: no client input may delay another robot's cycle.

Two `ur` robots (alice: UR10e, bob: UR3e) in one daemon against two in-process fakes on this run's
own addresses. Bob runs a goal while alice receives the worst inputs a client can send; bob's
program must never halt and his goal must succeed. Everything is asserted by counts and events:
the fake's program starts and stops, the goal's result, the daemon's restart counter.

Each fake runs its own event loop in a thread of its own, as a real robot runs apart from the
daemon: a stall of the daemon's loop must not stall the fake's clock and reverse-read timeout too.
"""

from __future__ import annotations

import asyncio
import json
import logging
import threading
from collections import Counter
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import pytest

from tests.helpers import acquire_lease, fake_address, free_tcp_port, swing_trajectory
from tests.integration.conftest import running_daemon
from urdaemon.client import Client
from urdaemon.fakeur.controller import FakeController
from urdaemon.publish.envelope import MAX_MESSAGE_BYTES, SMALL_MESSAGE_BYTES

pytestmark = pytest.mark.timeout(180)

HOME = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
BOB_TARGET = [-0.3, -1.7, 1.7, -1.6, -1.5, -0.2]


def _ports() -> str:
    p = [free_tcp_port() for _ in range(4)]
    return f"{{reverse: {p[0]}, script_sender: {p[1]}, trajectory: {p[2]}, script_command: {p[3]}}}"


def _cell(alice: str, bob: str) -> str:
    return f"""
cell: ingress
robots:
  - name: alice
    model: ur10e
    backend: ur
    address: {alice}
    headless: true
    pose: {{xyz: [0.6, 0.0, 0.0]}}
    ports: {_ports()}
    ur: {{startup: true, listen_address: 127.0.0.1}}
  - name: bob
    model: ur3e
    backend: ur
    address: {bob}
    headless: true
    pose: {{xyz: [-0.6, 0.0, 0.0]}}
    ports: {_ports()}
    ur: {{startup: true, listen_address: 127.0.0.1}}
"""


def _worst_inputs() -> list[tuple[str, bytes, bool]]:
    """(key under ingress/alice/, payload, put) of the worst inputs of issue 13's finding 2, as large
    as the daemon used to take them (2 MiB)."""
    numbers = ",".join(["0.1"] * 500_000)
    return [
        ("goal/move", f'{{"positions": [{numbers}]}}'.encode(), False),  # a 2 MB move
        (
            "goal/trajectory",
            json.dumps(swing_trajectory(5000, HOME)).encode(),
            False,
        ),  # 5 000 points, ~1.3 MB
        ("command/joint_position", json.dumps({"positions": [0.5] * 400_000}).encode(), True),
        ("service/set_payload", b'{"mass": ' + b"[" * 30_000 + b"]" * 30_000 + b"}", False),
        ("goal/move", b"x" * 1_000_000, False),
    ]


@asynccontextmanager
async def _fake_in_thread(model: str) -> AsyncIterator[FakeController]:
    """A fake controller serving from its own event loop in its own thread."""
    started = threading.Event()
    held: dict[str, Any] = {}

    async def serve() -> None:
        fake = FakeController(model, address=fake_address(), initial_positions=HOME)
        async with fake:
            held["fake"], held["loop"], held["stop"] = fake, asyncio.get_running_loop(), asyncio.Event()
            started.set()
            await held["stop"].wait()

    thread = threading.Thread(target=asyncio.run, args=(serve(),), name=f"fake-{model}", daemon=True)
    thread.start()
    loop = asyncio.get_running_loop()
    assert await loop.run_in_executor(None, started.wait, 30.0), "the fake did not start"
    try:
        yield held["fake"]
    finally:
        held["loop"].call_soon_threadsafe(held["stop"].set)
        await loop.run_in_executor(None, thread.join, 30.0)


async def _send(client: Client, key: str, payload: bytes, put: bool, token: bytes) -> list[dict[str, Any]]:
    """Send as the holder of alice's command lease (``token``): what is tested is each input's own
    cost and refusal, never the lease's."""
    if put:
        client.session.put(key, payload, attachment=token)
        return []

    def ask() -> list[dict[str, Any]]:
        return [
            json.loads(r.ok.payload.to_bytes())
            for r in client.session.get(key, payload=payload, attachment=token, timeout=30.0)
            if r.ok
        ]

    return await asyncio.get_running_loop().run_in_executor(None, ask)


async def _ready(client: Client, robot: str) -> None:
    sub = client.subscribe(f"ingress/{robot}/status", 1000)
    try:
        for _ in range(400):
            if (await sub.get_json(timeout=10.0))["ready"]:
                return
        raise AssertionError(f"{robot} never ready")
    finally:
        client.unsubscribe(sub)


async def test_bobs_program_never_halts_while_alice_gets_the_worst_inputs(
    caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Reproduction: while bob ran a goal, alice was sent a 2 MB move, a valid 5 000-point trajectory
    with velocities and accelerations, a 400 000-value stream command (each as large as the daemon
    took), deeply nested JSON and 1 MB of garbage. Decoding and checking each held the event loop for
    0.1-0.2 s: bob's program timed out on its 100 ms reverse read and halted, and his goal aborted
    (seen 3/3 on the old code)."""
    caplog.set_level(logging.INFO, logger="urdaemon")
    async with _fake_in_thread("ur10e") as fake_alice, _fake_in_thread("ur3e") as fake_bob:
        await _attack(fake_alice, fake_bob, monkeypatch)


async def _attack(
    fake_alice: FakeController, fake_bob: FakeController, monkeypatch: pytest.MonkeyPatch
) -> None:
    programs: Counter[str] = Counter()
    start_program, stop_program = fake_bob.programs.submit, fake_bob.arm.stop_program

    def started(*args: Any) -> None:
        programs["started"] += 1
        start_program(*args)

    def stopped() -> Any:
        programs["stopped"] += 1
        return stop_program()

    monkeypatch.setattr(fake_bob.programs, "submit", started)
    monkeypatch.setattr(fake_bob.arm, "stop_program", stopped)
    async with running_daemon(_cell(fake_alice.address, fake_bob.address)) as (daemon, client):
        await _ready(client, "alice")
        await _ready(client, "bob")
        bob = await client.robot("bob")
        lease = await acquire_lease(client.session, "ingress", "alice")
        assert programs["started"] == 1, programs
        before = Counter(programs)
        inputs = _worst_inputs()
        replies: list[dict[str, Any]] = []
        for _ in range(2):  # two goals of bob, each while alice gets every input
            goal = await bob.move(BOB_TARGET, duration=3.0)
            for key, payload, put in inputs:
                replies += await _send(client, f"ingress/alice/{key}", payload, put, lease.token)
                # the trajectory, if accepted
                await client.request("ingress/alice/goal/cancel", timeout=10.0, attachment=lease.token)
            result = await goal.result(timeout=30.0)
            assert result["status"] == "succeeded", result
            back = await bob.move(HOME, duration=1.0)
            assert (await back.result(timeout=30.0))["status"] == "succeeded"
        # every query of alice was answered (refused, or the trajectory accepted and then canceled)
        assert len(replies) == 2 * sum(1 for *_, put in inputs if not put), replies
        oversized = sum(
            1
            for key, payload, put in inputs
            if not put
            and len(payload) > (MAX_MESSAGE_BYTES if key == "goal/trajectory" else SMALL_MESSAGE_BYTES)
        )
        assert sum(1 for r in replies if "exceeds the limit" in r.get("reason", "")) == 2 * oversized, replies
        assert sum(1 for r in replies if r.get("accepted") is True) == 2, replies  # the trajectories
        # bob's program ran all along
        assert programs == before, programs  # no program stopped, none started again
        assert fake_bob.arm.program_running
        assert daemon.runtimes[1].status_message()["restarts"] == 0
        assert daemon.runtimes[1].backend.state.ready_for_motion
        assert fake_bob.arm.q == pytest.approx(HOME, abs=0.01)
