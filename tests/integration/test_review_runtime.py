"""Review of issue 13's fix: one slicing budget for the whole process, answers at shutdown, freeing
by explicit ownership, and every service (dashboard, cycle_stats too) on the one service path.

Runtimes on the mock backend without Zenoh (``test_review_planning``'s harness); waits are on replies,
cycles and turns of the event loop, bounded in count and time.
"""

from __future__ import annotations

import asyncio
import json
import sys
from collections import Counter
from collections.abc import Callable, Generator
from typing import Any

import pytest

from tests.integration.test_review_planning import Query, alice, trajectory
from urdaemon.control.trajectory import TrajectoryPlanner
from urdaemon.publish.services import spec
from urdaemon.publish.trajectory_json import TrajectoryGoalDecoder
from urdaemon.runtime import slicing

pytestmark = pytest.mark.timeout(60)


def turn_counter() -> tuple[Callable[[], int], Callable[[], None]]:
    """How many turns the event loop made (one callback rescheduled each turn), and how to stop it."""
    loop = asyncio.get_running_loop()
    turns = 0
    ticking = True

    def tick() -> None:
        nonlocal turns
        turns += 1
        if ticking:
            loop.call_soon(tick)

    def stop() -> None:
        nonlocal ticking
        ticking = False

    loop.call_soon(tick)
    return (lambda: turns), stop


def _recorded(
    steps: Generator[None, None, Any], turn: Callable[[], int], record: list[tuple[int, int]]
) -> Generator[None, None, Any]:
    """``steps``, each recorded with the turn of the loop it ran in and whose work it is."""
    owner = id(steps)
    while True:
        record.append((turn(), owner))
        try:
            next(steps)
        except StopIteration as stop:
            return stop.value
        yield


async def test_two_goals_decoded_at_once_run_one_slice_per_turn(monkeypatch: pytest.MonkeyPatch) -> None:
    """Reproduction: the slice budget was per task: two robots decoding big goals at once each ran a
    slice in the same turn of the loop (N robots: N × 0.25 ms per turn)."""
    turn, stop = turn_counter()
    steps: list[tuple[int, int]] = []
    payload = json.dumps(trajectory(3000)).encode()
    try:
        goals = await asyncio.gather(
            slicing.sliced(_recorded(TrajectoryGoalDecoder(payload).steps(), turn, steps)),
            slicing.sliced(_recorded(TrajectoryGoalDecoder(payload).steps(), turn, steps)),
        )
    finally:
        stop()
    assert [len(goal.points) for goal in goals] == [3000, 3000]
    turns_of: dict[int, set[int]] = {}
    for t, owner in steps:
        turns_of.setdefault(owner, set()).add(t)
    assert len(turns_of) == 2, turns_of.keys()
    assert min(len(turns) for turns in turns_of.values()) > 2  # both were sliced
    owners_per_turn = Counter(t for t, _ in set(steps))
    assert max(owners_per_turn.values()) == 1, [t for t, n in owners_per_turn.items() if n > 1][:10]


async def test_two_robots_planning_at_once_never_slice_in_the_same_turn(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Reproduction: two runtimes given 3000-point goals at once decoded and checked them side by
    side, both in the same turns of the loop."""
    slices: list[tuple[int, int]] = []
    turn, stop = turn_counter()
    sliced = slicing.sliced

    async def recording(steps: Generator[None, None, Any], check: Any = None) -> Any:
        return await sliced(_recorded(steps, turn, slices), check)

    monkeypatch.setattr(slicing, "sliced", recording)
    try:
        async with alice() as first, alice() as second:
            goals = [Query(c.key("goal/trajectory"), trajectory(3000)) for c in (first, second)]
            first.runtime.goals.on_trajectory_goal(goals[0])
            second.runtime.goals.on_trajectory_goal(goals[1])
            answers = [await goal.answer() for goal in goals]
    finally:
        stop()
    assert [a["accepted"] for a in answers] == [True, True], answers
    owners_per_turn: dict[int, set[int]] = {}
    for t, owner in slices:
        owners_per_turn.setdefault(t, set()).add(owner)
    shared = [t for t, owners in owners_per_turn.items() if len(owners) > 1]
    assert shared == [], f"{len(shared)} turns ran slices of two goals"


async def test_a_request_cancelled_before_it_started_is_answered() -> None:
    """Reproduction: at shutdown the runtime cancels its request tasks; one cancelled before its first
    step never reached its ``except CancelledError``, so its query got no reply at all."""
    async with alice() as cell:
        runtime = cell.runtime
        service = Query(cell.key("service/set_speed_slider"), {"fraction": 0.5})
        runtime.services.run(service, spec("set_speed_slider"))
        goal = Query(cell.key("goal/trajectory"), trajectory(10))
        runtime.goals.on_trajectory_goal(goal)
        pending = list(runtime.requests.tasks)
        assert len(pending) == 2
        for task in pending:
            task.cancel()  # before either ran a step
        await asyncio.gather(*pending, return_exceptions=True)
        assert [(r["ok"], r["reason"]) for r in service.replies] == [(False, "daemon shutting down")]
        assert [(r["accepted"], r["reason"]) for r in goal.replies] == [(False, "daemon shutting down")]
        assert runtime.controller.active_goal_id is None


async def test_requests_after_shutdown_began_are_refused() -> None:
    """Reproduction: while the daemon closed the backends (after the runtimes ended), new requests
    were still handled: a service acted, a move could be accepted with no cycle left to end it."""
    async with alice() as cell:
        runtime = cell.runtime
        acted: list[float] = []

        async def slider(fraction: float) -> None:
            acted.append(fraction)

        cell.backend.set_speed_slider = slider  # type: ignore[method-assign]
    # alice's runtime has ended (as at shutdown); its queryables stay declared until the session closes
    service = Query(cell.key("service/set_speed_slider"), {"fraction": 0.5})
    cell.node.handlers[runtime.keys.service("set_speed_slider")](service)
    move = Query(cell.key("goal/move"), {"positions": [0.1, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]})
    runtime.goals.on_move_goal(move)
    trajectory_goal = Query(cell.key("goal/trajectory"), trajectory(10))
    runtime.goals.on_trajectory_goal(trajectory_goal)
    for query in (service, move, trajectory_goal):
        answer = await query.answer()
        assert answer.get("reason") == "daemon shutting down", answer
    assert acted == []
    assert runtime.controller.active_goal_id is None


async def test_a_handed_over_planner_is_freed_whatever_the_interpreter_counts(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Reproduction: what to free in slices was decided by ``sys.getrefcount(obj) == 2``; an
    interpreter counting references differently (CPython 3.14 reports fewer: here, 1) freed nothing
    in slices, and one counting more would take apart a planner someone still used."""
    monkeypatch.setattr(sys, "getrefcount", lambda obj: 1)
    planner = TrajectoryPlanner.__new__(TrajectoryPlanner)
    shared = [float(i) for i in range(1000)]
    planner.__dict__.update(points=shared, velocities=[(0.0,) * 6 for _ in range(1000)])
    await slicing.release([planner])
    assert vars(planner) == {}, "the planner handed over was not taken apart"
    assert len(shared) == 1000, "a list it reached was changed"


async def test_dashboard_is_busy_while_it_runs_and_reports_bugs_as_internal_errors() -> None:
    """Reproduction: ``dashboard`` bypassed the one service path: two commands at once both ran (no
    busy refusal, unlike every other service), and a bug was answered "RuntimeError: boom" instead of
    "internal error: ..."."""
    async with alice() as cell:
        release = asyncio.Event()
        lines: list[str] = []

        async def dashboard(line: str) -> tuple[bool, str]:
            lines.append(line)
            if line == "boom":
                raise RuntimeError("boom")
            await release.wait()
            return True, "ok"

        cell.backend.dashboard = dashboard  # type: ignore[method-assign]
        handle = cell.node.handlers[cell.runtime.keys.service("dashboard")]
        first = Query(cell.key("service/dashboard"), {"command": "robotmode"})
        second = Query(cell.key("service/dashboard"), {"command": "robotmode"})
        handle(first)
        handle(second)
        busy = await second.answer()
        assert busy["ok"] is False, busy
        assert busy["reason"].startswith("busy: dashboard is still running"), busy
        release.set()
        assert await first.answer() == {"v": 1, "ok": True, "reply": "ok"}
        assert lines == ["robotmode"]
        bug = Query(cell.key("service/dashboard"), {"command": "boom"})
        handle(bug)
        answer = await bug.answer()
        assert answer["reason"] == "internal error: RuntimeError: boom", answer


async def test_cycle_stats_still_answers_on_the_service_path() -> None:
    """cycle_stats moved onto the service path: the same fields, and a bad payload is refused."""
    async with alice() as cell:
        handle = cell.node.handlers[cell.runtime.keys.service("cycle_stats")]
        stats = Query(cell.key("service/cycle_stats"), {})
        handle(stats)
        answer = await stats.answer()
        assert answer["ok"] is True, answer
        assert answer["cycles"] > 0, answer
        assert {"missed_cycles", "late_cycles", "turnaround"} <= set(answer)
        bad = Query(cell.key("service/cycle_stats"), {"reset": "yes"})
        handle(bad)
        assert (await bad.answer())["ok"] is False
