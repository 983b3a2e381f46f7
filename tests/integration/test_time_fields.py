"""Every message a running mock cell publishes, on every key, carries the time it describes (issue 29,
section 1; docs/keys.md, "Time fields"): an integer ``host_time_ns`` between the daemon's start and
the message's arrival, and ``controller_time`` wherever a robot's clock is known.

One subscriber follows ``<cell>/**`` while a robot goal and a cell goal run (feedback, results and
the cell's result) and a refused command and the leases make events; the test ends once every kind
of message was seen, bounded in time.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import pytest

from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.client import Client, Subscription, send_cell_trajectory

pytestmark = pytest.mark.timeout(120)

CELL = "testcell"
ROBOTS = ("alice", "bob")
ALICE = [0.3, -1.4, 1.4, -1.5, -1.6, 0.2]
BOB = [-0.3, -1.7, 1.7, -1.6, -1.5, -0.2]
HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
ROBOT_KEYS = ("joint_states", "tcp_pose", "status", "io", "events", "servo_command")
CLOCKED = ("joint_states", "tcp_pose", "status", "io", "feedback", "result", "servo_command")
"""Kinds of a robot's messages about its state: they carry its clock."""
EXPECTED = {"joint_states", "tcp_pose", "status", "io", "events", "tf", "feedback", "result", "cell_result"}


@dataclass
class Seen:
    """What the subscriber saw: messages by kind, and each robot's (host, controller) time pairs."""

    start_ns: int
    kinds: Counter[str] = field(default_factory=Counter)
    clocks: dict[str, list[tuple[int, float, str]]] = field(default_factory=dict)
    joint_states_seen: set[str] = field(default_factory=set)
    problems: list[str] = field(default_factory=list)
    all_seen: asyncio.Event = field(default_factory=asyncio.Event)


def kind_of(key: str) -> tuple[str, str | None] | None:
    """(kind, robot) of a published key; None for the client's own command puts."""
    parts = key.split("/")
    assert parts[0] == CELL, key
    if parts[1:] == ["tf"]:
        return "tf", None
    if len(parts) == 4 and parts[1] == "goal" and parts[3] == "result":
        return "cell_result", None
    if parts[1:] == ["audit"]:
        return "audit", None
    robot = parts[1]
    assert robot in ROBOTS, key
    if len(parts) == 5 and parts[2] == "goal" and parts[4] in ("feedback", "result"):
        return parts[4], robot
    if parts[2] == "command":
        return None
    assert len(parts) == 3, f"a key this test does not know: {key}"
    assert parts[2] in ROBOT_KEYS, f"a key this test does not know: {key}"
    return parts[2], robot


def check(seen: Seen, key: str, payload: bytes, received_ns: int) -> None:
    """Record the problems of one message's time fields."""
    found = kind_of(key)
    if found is None:
        return
    kind, robot = found
    data = json.loads(payload)
    seen.kinds[kind] += 1
    stamp = data.get("host_time_ns")
    if type(stamp) is not int or not seen.start_ns <= stamp <= received_ns:
        seen.problems.append(f"{key}: host_time_ns {stamp!r} not an int in [start, arrival]")
    if robot is not None and kind in CLOCKED:
        clock = data.get("controller_time")
        if isinstance(clock, float) and type(stamp) is int:
            seen.clocks.setdefault(robot, []).append((stamp, clock, kind))
        # before the robot's first state nothing knows its clock: only the status and IO say so
        elif not (clock is None and kind in ("status", "io") and robot not in seen.joint_states_seen):
            seen.problems.append(f"{key}: controller_time {clock!r}")
        if kind == "joint_states":
            seen.joint_states_seen.add(robot)
    elif kind == "events" and "controller_time" in data:
        seen.problems.append(f"{key}: an event carries controller_time")
    elif kind == "tf":
        check_tf(seen, data)
    elif kind == "cell_result":
        check_cell_result(seen, data)
    if kind == "tcp_pose" and data["pose"][:3] != data["position"]:
        seen.problems.append(f"{key}: pose {data['pose']} is not at position {data['position']}")
    if set(seen.kinds) >= EXPECTED:
        seen.all_seen.set()


def check_tf(seen: Seen, data: dict[str, Any]) -> None:
    times = data["robot_times"]
    assert set(times) == set(ROBOTS)
    for robot, stamp in times.items():
        if type(stamp["host_time_ns"]) is not int or not isinstance(stamp["controller_time"], float | None):
            seen.problems.append(f"tf: robot_times of {robot}: {stamp}")
    if data["host_time_ns"] != min(t["host_time_ns"] for t in times.values()):
        seen.problems.append(f"tf: host_time_ns {data['host_time_ns']} is not its oldest robot's")
    if "controller_time" in data:
        seen.problems.append("tf: a controller_time of no one robot")


def check_cell_result(seen: Seen, data: dict[str, Any]) -> None:
    if "controller_time" in data:
        seen.problems.append("cell result: a controller_time of no one robot")
    for robot, part in data["robots"].items():
        if not isinstance(part["controller_time"], float) or part["host_time_ns"] > data["host_time_ns"]:
            seen.problems.append(
                f"cell result: {robot}'s part {part['host_time_ns']}, {part['controller_time']}"
            )


async def follow(sub: Subscription, seen: Seen) -> None:
    while True:
        received = await sub.get_sample()
        check(seen, received.key, received.payload, time.time_ns())


async def test_every_message_on_every_key_carries_its_time() -> None:
    seen = Seen(start_ns=time.time_ns())
    async with running_daemon(TWO_MOCKS) as (_daemon, client):
        sub = client.subscribe(f"{CELL}/**", maxsize=100_000)
        following = asyncio.create_task(follow(sub, seen))
        try:
            await exercise(client)
            await asyncio.wait_for(seen.all_seen.wait(), 30.0)
        finally:
            following.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await following
    assert following.cancelled()  # it ended on the cancel, not on a failed check
    assert not seen.problems, seen.problems[:10]
    assert set(seen.kinds) >= EXPECTED, seen.kinds
    for robot in ROBOTS:  # each robot's messages tell one clock: its time goes on as the host's does
        pairs = sorted(seen.clocks[robot])
        assert len(pairs) > 10
        for (_, earlier, what), (_, later, other) in itertools.pairwise(pairs):
            assert later >= earlier, (robot, what, earlier, other, later)


async def exercise(client: Client) -> None:
    """A robot goal, a cell goal, a refused command: feedback, results, the cell's result, events."""
    client.session.put(f"{CELL}/alice/command/joint_position", b"garbage")  # no lease: refused, an event
    alice = await client.robot("alice")
    goal = await alice.move(ALICE, duration=1.0)
    feedback = 0
    async for message in goal.feedback():
        assert type(message["host_time_ns"]) is int
        assert isinstance(message["controller_time"], float)
        feedback += 1
    assert feedback > 0
    result = await goal.result(timeout=10)
    assert result["status"] == "succeeded"
    assert type(result["host_time_ns"]) is int
    assert isinstance(result["controller_time"], float)
    cell_goal = await send_cell_trajectory(
        client,
        CELL,
        {
            "alice": [{"positions": HOME, "time_from_start": 1.0}],
            "bob": [{"positions": BOB, "time_from_start": 1.0}],
        },
    )
    cell_result = await cell_goal.result(timeout=10)
    assert cell_result["status"] == "succeeded"
    assert type(cell_result["host_time_ns"]) is int
