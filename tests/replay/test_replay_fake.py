"""``urdaemon replay`` against fake UR controllers (the `ur` backend, headless, on loopback): a motion
recorded on the fake cell, replayed on it, follows the recorded (measured) path within 1e-4 rad.

The fake arm lags and smooths what it is commanded, so its measured moves last longer than they were
planned; the replay times each move by the recorded result of the goal that made it (goal_plan.py,
``moves``), so the fake is commanded the same plan again. The residual is where the arm came to rest
before each run, a hair off the commanded position. The measured worst error is printed."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import fake_address, free_tcp_port, run_cli_in_thread
from tests.integration.conftest import running_daemon
from tests.replay.recorder import Recorder, aligned_errors, settle
from urdaemon.backends.ur.backend import UrBackend
from urdaemon.client import Client
from urdaemon.fakeur.controller import FakeController
from urdaemon.fakeur.shared_clock import SharedClock

pytestmark = pytest.mark.timeout(180)

CELL = "urcell"
HOME = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
ALICE = [0.3, -1.4, 1.4, -1.5, -1.6, 0.2]
BOB = [-0.3, -1.7, 1.7, -1.6, -1.5, -0.2]


def _robot(name: str, model: str, address: str, x: float) -> str:
    p = [free_tcp_port() for _ in range(4)]
    ports = f"{{reverse: {p[0]}, script_sender: {p[1]}, trajectory: {p[2]}, script_command: {p[3]}}}"
    return f"""
  - name: {name}
    model: {model}
    backend: ur
    address: {address}
    headless: true
    pose: {{xyz: [{x}, 0.0, 0.0]}}
    ports: {ports}
    ur: {{startup: true, listen_address: 127.0.0.1}}"""


@asynccontextmanager
async def _fake_cell() -> AsyncIterator[tuple[str, Client, Any]]:
    """The cell file, a client, and the daemon's own session (what ``Recorder`` subscribes on: a
    subscriber there misses nothing the daemon publishes, where one across a link may, under load)."""
    clock = SharedClock(0.002, slots=1)
    fakes = {
        "alice": FakeController("ur10e", address=fake_address(), initial_positions=HOME),
        "bob": FakeController("ur3e", address=fake_address(), initial_positions=HOME),
    }
    for fake in fakes.values():
        fake.use_clock(clock, 0)
    text = f"cell: {CELL}\nrobots:" + "".join(
        (
            _robot("alice", "ur10e", fakes["alice"].address, 0.6),
            _robot("bob", "ur3e", fakes["bob"].address, -0.6),
        )
    )
    async with fakes["alice"], fakes["bob"], running_daemon(text) as (daemon, client):
        backends = [rt.backend for rt in daemon.runtimes]
        assert all(isinstance(b, UrBackend) for b in backends)

        def ready() -> bool:
            return all(b.state.ready_for_motion and b.servers.reverse.connected for b in backends)  # type: ignore[attr-defined]

        await fakes["alice"].until(ready, cycles=20_000, timeout=60.0)
        assert daemon.node is not None
        yield text, client, daemon.node.session


async def _at_rest(session: Any) -> None:
    """Until both fake arms report ten joint states in a row at rest (a goal succeeds within its
    tolerance while the measured arm still creeps the last hair)."""
    watch = Recorder(session, CELL).start()
    try:
        for _ in range(1000):
            tails = [watch.states(robot)[-10:] for robot in ("alice", "bob")]
            if all(len(t) == 10 and not any(any(s.velocities) for s in t) for t in tails):
                return
            await asyncio.sleep(0.01)
        raise AssertionError("the fake arms did not come to rest")
    finally:
        watch.close()


async def test_a_motion_recorded_on_the_fake_controllers_is_replayed_on_them(tmp_path: Path) -> None:
    async with _fake_cell() as (text, client, session):
        config = tmp_path / "cell.yaml"
        config.write_text(text)
        recorder = Recorder(session, CELL).start()
        await settle(recorder, "alice", 20)
        alice, bob = await client.robot("alice"), await client.robot("bob")
        goals = await asyncio.gather(alice.move(ALICE), bob.move(BOB))
        for goal in goals:
            assert (await goal.result(timeout=30))["status"] == "succeeded"
        await settle(recorder, "alice", 50)
        recorder.close()
        recording = recorder.write(tmp_path / "fake.mcap", await client.robot_description(CELL))
        back = await asyncio.gather(alice.move(HOME), bob.move(HOME))
        for goal in back:
            assert (await goal.result(timeout=30))["status"] == "succeeded"
        await alice.release()
        await bob.release()
        await _at_rest(session)
        replayed = Recorder(session, CELL).start()
        run = await run_cli_in_thread(
            "replay", str(recording), "--config", str(config), "--connect", client.endpoint, timeout=120
        )
        await settle(replayed, "alice", 20)
        replayed.close()
    assert run.code == 0, run.stderr + run.stdout
    for robot, target in (("alice", ALICE), ("bob", BOB)):
        states = replayed.states(robot)
        assert any(any(s.velocities) for s in states), (
            f"{robot}: {len(states)} replayed states, none moving: {run.stderr}{run.stdout}"
        )
        end = replayed.states(robot)[-1].positions
        assert max(abs(a - b) for a, b in zip(end, target, strict=True)) < 1e-3
        errors, missing = aligned_errors(recorder.states(robot), replayed.states(robot), 1.0)
        print(f"fake {robot}: worst {max(errors):.3g} rad over {len(errors)} samples, {missing} missed")
        assert max(errors) < 1e-4
