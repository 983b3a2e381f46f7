"""The daemon's contact, force mode and freedrive paths against a fake arm that touches things.

The fake's surroundings (urdaemon/fakeur/contact.py) put a wall or a hand's push on the tool; our control
script, running in the fake's interpreter, answers it through ``tool_contact``, ``force_mode`` and
``freedrive_mode`` as it would on a robot. Before the surroundings existed the fake arm moved in free air:
``tool_contact`` always answered 0, force mode and freedrive moved nothing and the TCP force read zero, so
each of these tests failed there (seen on f5f0e26: no contact event, a TCP force of 0, no motion).
"""

from __future__ import annotations

import math
from typing import Any

import pytest

from tests.helpers import rtde_sample
from tests.ur.test_ur_backend import HOME, _until
from tests.ur.test_ur_handguiding import _ready_alice
from urdaemon.fakeur.contact import Wall, surroundings_of
from urdaemon.fakeur.controller import FakeController
from urdaemon.model import SafetyMode

pytestmark = pytest.mark.timeout(90)

TOUCH_TOLERANCE_M = 1e-3
"""m: how far from the wall's surface the arm may rest after going back to where it touched (a cycle's
travel at the goal's speed is 0.3 mm)."""
FORCE_TOLERANCE_N = 1.0
"""N: how close force mode settles to the commanded force."""


def _position(fake: FakeController) -> tuple[float, float, float]:
    pose = fake.arm.actual_tcp_pose()
    return (pose[0], pose[1], pose[2])


async def _tcp_force(address: str) -> tuple[float, ...]:
    """RTDE ``actual_TCP_force`` read with our own codec, as a second client of the fake."""
    value = (await rtde_sample(address, ("actual_TCP_force",)))["actual_TCP_force"]
    assert isinstance(value, tuple), value
    return tuple(float(v) for v in value)


async def _cycles(fake: FakeController, count: int) -> None:
    """Until the fake has run ``count`` more cycles (woken by its ticks, bounded in time)."""
    await fake.cycles_pass(count, timeout=40.0)


async def _event(events: Any, kind: str) -> dict[str, Any]:
    for _ in range(200):
        event: dict[str, Any] = await events.get_json(timeout=20.0)
        if event["kind"] == kind:
            return event
    raise AssertionError(f"no {kind} event")


async def _touch_a_wall(
    fake: FakeController, client: Any, alice: Any
) -> tuple[Wall, dict[str, Any], dict[str, Any]]:
    """Arm tool contact and move toward a wall across the goal's path; the wall, the contact event
    and the goal's result, once the arm rests (bounded)."""
    target = [0.1, *HOME[1:]]
    start = _position(fake)
    end = fake.arm.kinematics.tool_pose(target)[:3]
    chord = [e - s for s, e in zip(start, end, strict=True)]
    length = math.sqrt(sum(c * c for c in chord))
    normal = tuple(-c / length for c in chord)  # the free side faces the start
    point = tuple(s + 0.5 * c for s, c in zip(start, chord, strict=True))
    wall = Wall.of(point, normal)
    surroundings_of(fake.arm).walls.append(wall)
    events = client.subscribe(alice.keys.events, 200)
    assert (await alice.start_tool_contact())["ok"] is True
    goal = await alice.move(target, duration=2.0)
    event = await _event(events, "tool_contact")
    result = await goal.result(timeout=30)
    for _ in range(2000):  # until the arm rests back at the touch point
        await _cycles(fake, 10)
        if not any(fake.arm.qd) and fake.arm.steady:
            break
    return wall, event, result


def _gap(wall: Wall, fake: FakeController) -> float:
    """m: the TCP's signed distance from the wall's surface (negative inside)."""
    return sum((p - w) * n for p, w, n in zip(_position(fake), wall.point, wall.normal, strict=True))


async def test_tool_contact_stops_a_goal_at_a_wall_and_goes_back_to_the_touch_point() -> None:
    """Arm tool contact, move toward a wall: the robot reports the contact, the goal is aborted, the arm
    stops and rests at the wall's surface (within a millimetre), never protective-stopped, and stays
    there when detection ends."""
    async with _ready_alice() as (fake, _, client, alice):
        wall, event, result = await _touch_a_wall(fake, client, alice)
        assert event["text"] == "contact", event
        assert result["status"] == "aborted", result
        # at once, naming the contact (before, it ran out 1 s after the goal's end: "tolerance not reached")
        assert result["reason"].startswith("tool contact"), result
        assert not any(fake.arm.qd), "the robot stopped"
        assert fake.arm.safety_mode is SafetyMode.NORMAL, "stopped by the contact, not by a safety stop"
        assert abs(_gap(wall, fake)) < TOUCH_TOLERANCE_M, _gap(wall, fake)
        rest = list(fake.arm.q)
        assert (await alice.end_tool_contact())["ok"] is True
        await _cycles(fake, 500)  # 1 s: ending detection must not send the arm on toward the old goal
        assert fake.arm.q == pytest.approx(rest, abs=1e-6)


async def test_tool_contact_goes_back_to_before_the_force_rose() -> None:
    """After a contact the arm rests where the force had not yet risen: on the free side of the wall, no
    force. Our control script (ud_check_tool_contact) used to stop first and read the history after, when
    steps_back no longer counted from the current cycle: it went back to a pose ~0.5 mm inside the wall
    (10 N) at this goal's speed."""
    async with _ready_alice() as (fake, _, client, alice):
        wall, event, _ = await _touch_a_wall(fake, client, alice)
        assert event["text"] == "contact", event
        assert _gap(wall, fake) >= 0.0, _gap(wall, fake)
        assert max(abs(f) for f in fake.arm.tcp_force[:3]) == 0.0, fake.arm.tcp_force


async def test_force_mode_pressing_into_a_wall_settles_at_the_commanded_force() -> None:
    """Force mode pushing down 20 N onto a wall 5 mm below the tool: the tool sinks in until the wall
    pushes back 20 N, as RTDE ``actual_TCP_force`` shows (+20 N: the wall pushes the tool up)."""
    async with _ready_alice() as (fake, _, client, alice):
        x, y, z = _position(fake)
        wall = Wall.of((x, y, z - 0.005), (0.0, 0.0, 1.0))
        surroundings_of(fake.arm).walls.append(wall)
        reply = await alice.start_force_mode(
            [0.0] * 6, [0, 0, 1, 0, 0, 0], [0.0, 0.0, -20.0, 0.0, 0.0, 0.0], [0.1] * 6
        )
        assert reply["ok"] is True, reply
        await _until(client, alice.keys.joint_states, lambda m: fake.arm.force_mode, limit=2000)
        await _cycles(fake, 1000)  # 2 s of controller time
        force = await _tcp_force(fake.address)
        assert force[2] == pytest.approx(20.0, abs=FORCE_TOLERANCE_N), force
        assert max(abs(f) for f in (*force[:2], *force[3:])) < FORCE_TOLERANCE_N, force
        assert wall.depth(_position(fake)) == pytest.approx(20.0 / wall.stiffness, abs=1e-4)
        assert fake.arm.safety_mode is SafetyMode.NORMAL
        assert (await alice.end_force_mode())["ok"] is True


async def test_freedrive_moves_the_tool_along_a_push_and_stops_when_it_goes() -> None:
    """Freedrive on, a 20 N push along +y: the TCP goes along +y (not across it); the push gone, it stays."""
    async with _ready_alice() as (fake, _, _, alice):
        states = alice.joint_states(10_000)
        surroundings = surroundings_of(fake.arm)
        start = _position(fake)
        await alice.ensure_lease()  # stream commands need the lease held first; they never wait for it
        for _ in range(40):  # freedrive commands every 5 cycles keep its deadman alive
            alice.freedrive(True)
            for _ in range(5):
                await states.get(timeout=5.0)
            if fake.arm.freedrive:
                break
        assert fake.arm.freedrive is True
        surroundings.push[1] = 20.0
        pushed_at = fake.cycles
        for _ in range(400):
            alice.freedrive(True)
            for _ in range(5):
                await states.get(timeout=5.0)
            if fake.cycles >= pushed_at + 200:
                break
        moved = [p - s for p, s in zip(_position(fake), start, strict=True)]
        assert moved[1] > 0.01, moved
        assert abs(moved[0]) < 0.1 * moved[1], moved
        assert abs(moved[2]) < 0.1 * moved[1], moved
        surroundings.push[1] = 0.0
        await _cycles(fake, 2)
        still = _position(fake)
        for _ in range(20):
            alice.freedrive(True)
            for _ in range(5):
                await states.get(timeout=5.0)
        assert fake.arm.freedrive is True
        assert _position(fake) == pytest.approx(still, abs=1e-9), "no push: the arm stays"
        assert not any(fake.arm.qd)
        alice.freedrive(False)
