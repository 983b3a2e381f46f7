"""Between a tool contact and ``end_tool_contact`` nothing moves the robot, and after it motion starts from
where the robot rests.

Found by review: after a contact the daemon went idle, a client that kept streaming started a new
stream the robot ignored (its script rests in contact mode), the daemon's setpoint drifted away from the
robot, and ``end_tool_contact`` then servoed the robot to that setpoint in one step: into the wall,
protective stop (reproduced on 0dd9381).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import AsyncIterator
from typing import Any

import pytest

from tests.ur.test_ur_backend import HOME
from tests.ur.test_ur_handguiding import _ready_alice
from urdaemon.errors import GoalRejected
from urdaemon.fakeur.contact import Wall, surroundings_of
from urdaemon.fakeur.controller import FakeController
from urdaemon.model import SafetyMode

pytestmark = pytest.mark.timeout(90)

STEP = 0.2 * 0.002
"""rad per cycle the client's stream advances joint 0 toward the wall (0.2 rad/s)."""


def _position(fake: FakeController) -> tuple[float, float, float]:
    pose = fake.arm.actual_tcp_pose()
    return (pose[0], pose[1], pose[2])


def _wall_across(fake: FakeController, target: list[float], fraction: float) -> None:
    """A wall across the TCP's way to ``target``, ``fraction`` of the way there."""
    start = _position(fake)
    end = fake.arm.kinematics.tool_pose(target)[:3]
    chord = [e - s for s, e in zip(start, end, strict=True)]
    length = math.sqrt(sum(c * c for c in chord))
    normal = tuple(-c / length for c in chord)
    point = tuple(s + fraction * c for s, c in zip(start, chord, strict=True))
    surroundings_of(fake.arm).walls.append(Wall.of(point, normal))


@contextlib.asynccontextmanager
async def _collected(client: Any, key: str) -> AsyncIterator[list[dict[str, Any]]]:
    """Every event published on ``key`` while the block runs, in a list the test reads as it goes."""
    events = client.subscribe(key, 1000)
    seen: list[dict[str, Any]] = []

    async def collect() -> None:
        while True:
            seen.append(await events.get_json())

    task = asyncio.create_task(collect())
    try:
        yield seen
    finally:
        task.cancel()
        client.unsubscribe(events)


def _kinds(seen: list[dict[str, Any]], kind: str) -> list[dict[str, Any]]:
    return [event for event in seen if event["kind"] == kind]


async def test_a_contact_refuses_motion_until_it_ends_and_then_nothing_jumps() -> None:
    async with _ready_alice() as (fake, _, client, alice), _collected(client, alice.keys.events) as seen:
        _wall_across(fake, [HOME[0] + 0.4, *HOME[1:]], 0.1)
        states = alice.joint_states(10_000)
        assert (await alice.start_tool_contact())["ok"] is True
        await alice.ensure_lease()  # stream commands need the lease held first; they never wait for it
        for k in range(1500):  # stream toward the wall until the robot reports the contact
            if _kinds(seen, "tool_contact"):
                break
            alice.stream_positions([HOME[0] + STEP * k, *HOME[1:]])
            await states.get(timeout=5.0)
        assert [e["text"] for e in _kinds(seen, "tool_contact")] == ["contact"], seen
        for _ in range(3000):  # the robot goes back to where it touched and rests there
            await states.get(timeout=5.0)
            if fake.arm.steady:
                break
        rest = list(fake.arm.q)
        before = len(seen)
        # the client keeps streaming past the touch point: refused, naming the contact (a command the
        # daemon had no turn to read before a newer one came is refused as replaced)
        for _ in range(50):
            alice.stream_positions([rest[0] + 0.03, *rest[1:]])
            await states.get(timeout=5.0)
        reasons = [event["reason"] for event in _kinds(seen[before:], "command_rejected")]
        assert sum("tool contact" in reason for reason in reasons) >= 1, reasons
        assert all("tool contact" in reason or "replaced by a newer one" in reason for reason in reasons)
        with pytest.raises(GoalRejected, match="tool contact"):
            await alice.move([rest[0] + 0.03, *rest[1:]], duration=1.0)
        assert fake.arm.q == pytest.approx(rest, abs=1e-9), "nothing moved the robot"
        assert (await alice.end_tool_contact())["ok"] is True
        # now a stream to where the robot rests starts there: no jump toward an old setpoint
        for _ in range(200):
            alice.stream_positions(rest)
            await states.get(timeout=5.0)
            assert fake.arm.q == pytest.approx(rest, abs=1e-4)
        assert fake.arm.safety_mode is SafetyMode.NORMAL
