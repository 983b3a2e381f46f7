"""A cell goal on two `ur` robots against two fake controllers (issue 16: "a cell goal starts alice and
bob within one cycle of each other, measured from their controller timestamps on the fake, and bob is
stopped when alice aborts").

Both fakes (UR10e alice, UR3e bob, both 500 Hz) tick on one shared clock in one slot, so every cycle
steps both arms in the same callback: the difference of the two arms' timestamps is a constant, and a
moment of one converts to the other's. When an arm's commanded position first leaves where it rested
is read from the fake itself (its target after each cycle). Before the cell goal there was no way to
start both together; two goals sent one after the other start as far apart as the round trips between.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any

import pytest

from tests.helpers import fake_address, free_tcp_port
from tests.integration.conftest import running_daemon
from urdaemon.backends.ur.backend import UrBackend
from urdaemon.client import Client, send_cell_trajectory
from urdaemon.daemon import Daemon
from urdaemon.fakeur.controller import FakeController
from urdaemon.fakeur.shared_clock import SharedClock

pytestmark = pytest.mark.timeout(120)

HOME = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
ALICE = [0.3, -1.4, 1.4, -1.5, -1.6, 0.2]
BOB = [-0.3, -1.7, 1.7, -1.6, -1.5, -0.2]
PERIOD = 0.002
"""Both arms' controller cycle (e-Series)."""


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


@dataclass
class Cell:
    daemon: Daemon
    client: Client
    fakes: dict[str, FakeController]
    started: dict[str, float]
    """Each arm's timestamp after the first cycle its commanded position left where it rested."""


def _record_start(name: str, fake: FakeController, started: dict[str, float]) -> None:
    """Record, after every cycle, whether the arm's commanded position left ``HOME`` (exactly)."""
    arm = fake.arm
    step: Callable[[float], None] = arm.step

    def record(dt: float) -> None:
        step(dt)
        if name not in started and arm.target_q != HOME:
            started[name] = arm.timestamp

    arm.step = record  # type: ignore[method-assign]


@asynccontextmanager
async def _cell() -> AsyncIterator[Cell]:
    clock = SharedClock(PERIOD, slots=1)  # one callback steps both arms: one controller instant
    fakes = {
        "alice": FakeController("ur10e", address=fake_address(), initial_positions=HOME),
        "bob": FakeController("ur3e", address=fake_address(), initial_positions=HOME),
    }
    started: dict[str, float] = {}
    for name, fake in fakes.items():
        fake.use_clock(clock, 0)
        _record_start(name, fake, started)
    text = "cell: urcell\nrobots:" + "".join(
        (
            _robot("alice", "ur10e", fakes["alice"].address, 0.6),
            _robot("bob", "ur3e", fakes["bob"].address, -0.6),
        )
    )
    async with fakes["alice"], fakes["bob"], running_daemon(text) as (daemon, client):
        cell = Cell(daemon, client, fakes, started)
        await _ready(cell)
        yield cell


async def _ready(cell: Cell) -> None:
    """Both robots ready for motion with their control program connected back."""
    backends = [rt.backend for rt in cell.daemon.runtimes]
    assert all(isinstance(b, UrBackend) for b in backends)

    def ready() -> bool:
        return all(b.state.ready_for_motion and b.servers.reverse.connected for b in backends)  # type: ignore[attr-defined]

    await cell.fakes["alice"].until(ready, cycles=20_000, timeout=60.0)


def _offset(cell: Cell) -> float:
    """alice's timestamp less bob's: the same at every moment (both step in one callback)."""
    return cell.fakes["alice"].arm.timestamp - cell.fakes["bob"].arm.timestamp


def _points(target: list[float], duration: float) -> list[dict[str, Any]]:
    return [{"positions": target, "time_from_start": duration}]


async def test_alice_and_bob_start_within_one_cycle_of_each_other() -> None:
    async with _cell() as cell:
        offset = _offset(cell)
        assert cell.started == {}, "neither arm moved before the goal"
        goal = await send_cell_trajectory(
            cell.client, "urcell", {"alice": _points(ALICE, 0.8), "bob": _points(BOB, 0.8)}
        )
        await cell.fakes["alice"].until(lambda: len(cell.started) == 2, cycles=5000)
        assert _offset(cell) == offset, "the two arms stepped together throughout"
        # bob's start on alice's time line
        apart = abs(cell.started["alice"] - (cell.started["bob"] + offset))
        assert apart <= PERIOD + 1e-9, (apart, cell.started, offset)
        result = await goal.result(timeout=30.0)
        assert result["status"] == "succeeded", result
        assert cell.fakes["alice"].arm.q == pytest.approx(ALICE, abs=0.01)
        assert cell.fakes["bob"].arm.q == pytest.approx(BOB, abs=0.01)


async def test_a_protective_stop_of_alice_stops_bob() -> None:
    async with _cell() as cell:
        goal = await send_cell_trajectory(
            cell.client, "urcell", {"alice": _points(ALICE, 4.0), "bob": _points(BOB, 4.0)}
        )
        alice, bob = cell.fakes["alice"], cell.fakes["bob"]
        await alice.until(lambda: len(cell.started) == 2, cycles=5000)
        await alice.cycles_pass(250)  # half a second into the motion
        alice.protective_stop()  # as if alice hit something
        result = await goal.result(timeout=30.0)
        assert result["status"] == "aborted", result
        assert result["reason"].startswith("robot 'alice' ended aborted: "), result
        assert "protective" in result["robots"]["alice"]["reason"].lower(), result
        bob_result = result["robots"]["bob"]
        assert bob_result["status"] == "aborted"
        assert bob_result["reason"].startswith(f"cell goal {goal.goal_id}: robot 'alice' ended aborted: ")
        # bob comes to rest short of its target
        await bob.until(lambda: not any(bob.arm.qd), cycles=5000)
        assert max(abs(q - t) for q, t in zip(bob.arm.q, BOB, strict=True)) > 0.05, bob.arm.q
