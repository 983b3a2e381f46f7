"""Nothing moves the robot while a linear goal is planned from where it rests (review of issue 17).

A linear goal's plan is the joints of every cycle from where the robot rested when planning began, made
in slices over up to seconds. A twist, a joint stream or a move goal accepted meanwhile moved the robot;
at rest again within the old start tolerance (1e-3 rad), the plan was accepted and its first cycle
stepped back to the stale start. Here, on the mock through Zenoh (the module daemon of
test_cartesian.py, with its lease), the planning is held before its first slice as the suite's own test
holds it; each of them is refused as busy naming the goal being planned, the robot never moves (every
joint state counted while they are refused), and let go, the goal runs from where the robot rests.

Reproduction: on the code before the gate's ``from_rest`` (dd4200c^) the twist is accepted and moves
the robot, so the test fails at the twist's refusal.
"""

from __future__ import annotations

import asyncio
import json
from typing import Any

import pytest

from tests.integration.test_cartesian import WAIT_S, Served, _drain, _home, _shifted, served  # noqa: F401
from urdaemon.client import Subscription

pytestmark = [pytest.mark.timeout(180), pytest.mark.asyncio(loop_scope="module")]

BUSY = (
    "busy: a linear goal is being planned from where the robot rests (linear goal of 1 pose); "
    "wait for its answer or cancel it"
)
STATES_WHILE_REFUSED = 25
"""Joint states (50 ms at 500 Hz) checked at rest after each refusal: a twist or stream accepted would
have moved the robot within a cycle or two."""


async def _rejected(events: Subscription) -> str:
    """The reason of the next ``command_rejected`` event."""
    for _ in range(1000):
        event = await events.get_json(WAIT_S)
        if event.get("kind") == "command_rejected":
            return str(event["reason"])
    raise AssertionError("no command_rejected event")


async def _still(states: Subscription, before: list[float]) -> None:
    """The next ``STATES_WHILE_REFUSED`` joint states: every joint where it was, at rest."""
    for _ in range(STATES_WHILE_REFUSED):
        sample = json.loads((await states.get(timeout=WAIT_S))[1])
        assert sample["position"] == before, "the robot moved while a linear goal was planned"
        assert all(v == 0.0 for v in sample["velocity"]), sample["velocity"]


async def test_nothing_moves_the_robot_while_a_linear_goal_is_planned(
    served: Served,  # noqa: F811
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from urdaemon.runtime import slicing

    await _home(served)
    real = slicing.sliced
    uses = 0
    go = asyncio.Event()

    async def held(steps: Any, check: Any = None) -> Any:
        nonlocal uses
        uses += 1
        if uses == 2:  # the first use decodes the goal, the second plans it: held before its first slice
            await go.wait()
        return await real(steps, check)

    monkeypatch.setattr(slicing, "sliced", held)
    before = served.positions
    end = _shifted(served.kin.forward(before), dz=0.05)
    states = served.alice.joint_states(100_000)
    events = served.client.subscribe("cartd/alice/events", 1000)
    planning = asyncio.create_task(served.ask("goal/linear", {"poses": [end]}))
    try:
        for _ in range(100_000):  # bounded: the goal reaches the planner within a few turns of the loop
            if uses == 2:
                break
            await asyncio.sleep(0)
        assert uses == 2
        for key, body in (
            ("command/twist", {"linear": [0.0, 0.0, 0.0], "angular": [0.0, 0.0, 0.008]}),
            ("command/joint_velocity", {"velocities": [0.0, 0.0, 0.0, 0.012, 0.0, 0.0]}),
        ):
            _drain(states)  # only joint states from the put on are checked
            served.client.session.put(
                f"cartd/alice/{key}", json.dumps(body).encode(), attachment=served.token
            )
            await _still(states, before)
            assert (await _rejected(events)) == BUSY, key
        moved = [*before[:3], before[3] + 0.01, *before[4:]]
        move = await served.ask("goal/move", {"positions": moved})
        assert move == {"v": 1, "accepted": False, "reason": BUSY}
        await _still(states, before)
    finally:
        go.set()
        served.client.unsubscribe(events)
    try:
        reply = await planning
        assert reply["accepted"] is True, reply
        steps = await _first_steps(states, before, 3)
    finally:
        served.client.unsubscribe(states)
    assert (await served.result(reply["goal_id"]))["status"] == "succeeded"
    # It starts where the robot rests: its first cycles move by the jerk-limited ramp from rest (well
    # under a micro-radian), not by a step to a stale start (0.6 mrad in the review's repro).
    assert max(steps) < 1e-6, steps


async def _first_steps(states: Subscription, rest: list[float], count: int) -> list[float]:
    """The largest joint change of each of the first ``count`` cycles that move from ``rest``."""
    prev = rest
    steps: list[float] = []
    for _ in range(100_000):
        q = json.loads((await states.get(timeout=WAIT_S))[1])["position"]
        step = max(abs(a - b) for a, b in zip(q, prev, strict=True))
        prev = q
        if step > 0.0 or steps:
            steps.append(step)
        if len(steps) == count:
            return steps
    raise AssertionError("the linear goal did not move the robot")
