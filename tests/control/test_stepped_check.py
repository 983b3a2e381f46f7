"""A long trajectory goal is checked, accepted and freed in small steps, never in one long call.

Reproduction (issue 13, finding 2): a valid 5 000-point trajectory held the event loop once for
~1.4 ms after the daemon had sliced its decoding: the controller's point check was one call of
~10 µs a point (the daemon paused it from a worker thread with a profile hook), accepting the goal
walked every segment (``TrajectoryPlanner.finish``, ~1.3 ms) and ending it freed the whole plan at
once (~1.5 ms). Each test below names the old behaviour it fails on.
"""

from __future__ import annotations

import asyncio
import math
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.helpers import Stepped
from urdaemon.control import GoalStatus, MotionController, PlannedTrajectory, TrajectoryPoint
from urdaemon.control.ledger import RELEASE_SEGMENTS
from urdaemon.control.trajectory import TrajectoryPlanner
from urdaemon.errors import GoalRejected
from urdaemon.model import UR_JOINTS
from urdaemon.runtime import slicing

from .sim import PERIOD, THREE_LIMITS, UR10E_LIMITS, SimRobot, ready_state

NAMES = THREE_LIMITS.names


def _outcome(run: Any) -> tuple[Any, ...]:
    """What a check ends with: its refusal, or the planner's points and boundary velocities."""
    try:
        planner = run()
    except GoalRejected as err:
        return ("rejected", err.reason)
    return ("planned", planner.points, planner.velocities)


def _stepped(check: Stepped[TrajectoryPlanner], sizes: list[int]) -> tuple[TrajectoryPlanner, int]:
    """Run ``check`` with step sizes taken round-robin from ``sizes``; the planner and the calls made."""
    for calls in range(1, 100_000):
        if not check.step(sizes[calls % len(sizes)]):
            return check.result(), calls
    raise AssertionError("the check did not end")


def _rarely(fault: st.SearchStrategy[Any], usual: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    """``usual``, and one time in sixteen ``fault``."""
    return st.integers(0, 15).flatmap(lambda r: fault if r == 0 else usual)


_wrong_length = st.sampled_from([2, 4]).flatmap(
    lambda n: st.lists(st.floats(-1.0, 1.0), min_size=n, max_size=n)
)
_coordinate = _rarely(st.sampled_from([math.nan, math.inf, -math.inf, 1.5, -3.0]), st.floats(-0.45, 0.45))
_positions = _rarely(_wrong_length, st.lists(_coordinate, min_size=3, max_size=3)).map(tuple)
_rates = _rarely(
    st.one_of(
        _wrong_length, st.lists(st.sampled_from([math.nan, 4.5, -4.9, 6.0, 40.0]), min_size=3, max_size=3)
    ),
    st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3),
).map(tuple)

_at_rest = _rarely(_rates, st.just((0.0,) * 3))


@st.composite
def _trajectories(draw: st.DrawFn) -> tuple[tuple[str, ...], list[TrajectoryPoint]]:
    names = draw(_rarely(st.just(("a", "b", "x")), st.permutations(NAMES).map(tuple)))
    count = draw(st.integers(0, 10))
    points: list[TrajectoryPoint] = []
    t = 0.0
    for k in range(count):
        t += draw(_rarely(st.sampled_from([0.0, -0.5, math.nan, 1e5]), st.sampled_from([0.5, 1.0, 2.0])))
        last = k == count - 1
        points.append(
            TrajectoryPoint(
                positions=draw(_positions),
                time_from_start=t,
                velocities=draw(
                    st.one_of(st.none(), _rarely(_rates, st.just((0.0,) * 3)) if last else _rates)
                ),
                accelerations=draw(
                    st.one_of(st.none(), _rarely(_rates, st.just((0.0,) * 3)) if last else _rates)
                ),
            )
        )
    return names, points


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=_trajectories(), sizes=st.lists(st.integers(1, 7), min_size=1, max_size=4))
def test_the_stepped_check_ends_as_the_one_shot_check_does(
    case: tuple[tuple[str, ...], list[TrajectoryPoint]], sizes: list[int]
) -> None:
    """Property: whatever the step sizes, checking a trajectory in steps refuses it with the same
    reason, or accepts it with the same points and velocities, as the one-shot check.
    Old code: ``MotionController.check_trajectory`` did not exist; the check was one call."""
    names, points = case
    controller = MotionController(THREE_LIMITS, period=PERIOD)
    state = ready_state(NAMES, [0.1, -0.2, 0.3])
    one_shot = _outcome(lambda: controller.prepare_trajectory(names, points, state))
    stepped = _outcome(lambda: _stepped(Stepped(controller.check_trajectory(names, points, state)), sizes)[0])
    assert stepped == one_shot


START = [0.0, -1.5, 1.5, -1.5, -1.5, 0.0]


def _ur_points(count: int, *, fault_at: int | None = None) -> list[TrajectoryPoint]:
    """A slow swing from START through ``count`` points 10 ms apart with their velocities and
    accelerations, the last at rest a second later; one position NaN at ``fault_at``."""
    points = []
    for k in range(count - 1):
        t = 0.5 + 0.01 * k
        positions = tuple(p + 0.05 * (1.0 - math.cos(t)) for p in START)
        if k == fault_at:
            positions = (math.nan, *positions[1:])
        points.append(TrajectoryPoint(positions, t, (0.05 * math.sin(t),) * 6, (0.05 * math.cos(t),) * 6))
    t = 0.5 + 0.01 * (count - 2)
    end = tuple(p + 0.05 * (1.0 - math.cos(t)) for p in START)
    if fault_at == count - 1:
        end = (math.nan, *end[1:])
    points.append(TrajectoryPoint(end, t + 1.0))
    return points


def test_the_check_takes_a_step_per_point_and_finds_a_late_fault_late() -> None:
    """Each step checks a bounded piece (about a point), so a 500-point check takes more than 500
    calls of ``step(1)``; a fault in the last point is found only when the check reaches it.
    Old code: one ``prepare_trajectory`` call checked every point at once."""
    controller = MotionController(UR10E_LIMITS, period=PERIOD)
    state = ready_state(UR_JOINTS, START)
    planner, calls = _stepped(Stepped(controller.check_trajectory(UR_JOINTS, _ur_points(500), state)), [1])
    assert calls > 500
    assert len(planner.points) == 500

    check = Stepped(controller.check_trajectory(UR_JOINTS, _ur_points(500, fault_at=499), state))
    for _ in range(499):  # mapping the points into the controller's order, then the checks
        assert check.step(1)
    with pytest.raises(GoalRejected, match="point 499 positions"):
        _stepped(check, [1])
    assert not check.step(1)  # a refused check is over
    with pytest.raises(RuntimeError):
        check.result()


def test_an_abandoned_check_stops_and_has_no_result() -> None:
    """Old code: a check abandoned mid-way was a worker thread ended at its next function call."""
    controller = MotionController(UR10E_LIMITS, period=PERIOD)
    state = ready_state(UR_JOINTS, START)
    check = Stepped(controller.check_trajectory(UR_JOINTS, _ur_points(50), state))
    assert check.step(10)
    check.close()
    assert not check.step(10)
    with pytest.raises(RuntimeError, match="not finished"):
        check.result()


def _planned_tail(count: int) -> TrajectoryPlanner:
    controller = MotionController(UR10E_LIMITS, period=PERIOD)
    state = ready_state(UR_JOINTS, START)
    planner = controller.prepare_trajectory(UR_JOINTS, _ur_points(count), state)
    for _ in planner.tail_steps():
        pass
    return planner


class _Untouchable:
    """Stands in for a planned tail segment that ``finish`` must not look at."""

    def __getattr__(self, name: str) -> Any:
        raise AssertionError(f"finish looked at a tail segment ({name})")


def test_finishing_a_planned_tail_does_not_walk_its_segments() -> None:
    """Accepting a long goal costs one segment: the tail's start times were kept as it was planned.
    Old code: ``finish`` summed every segment's duration and copied the segment list (~1.3 ms for
    5 000 points, in one call on the loop)."""
    planner = _planned_tail(200)
    segments = planner._segments
    assert segments is not None
    assert len(segments) == 200
    tail_time = sum(float(s.duration) for s in segments[1:])
    for k in range(1, 199):  # the last one gives the plan its final state
        segments[k] = _Untouchable()
    start = START
    plan = planner.finish(start, [0.0] * 6, [0.0] * 6)
    first = float(plan._trajs[0].duration)
    assert plan.duration == pytest.approx(first + tail_time, abs=1e-9)
    assert plan.segment_count == 200
    with pytest.raises(RuntimeError, match="already finished"):
        planner.finish(start, [0.0] * 6, [0.0] * 6)


def test_a_plan_with_kept_start_times_samples_as_one_with_summed_start_times() -> None:
    """The plan ``finish`` hands over (tail starts counted from the end of segment 0) is the same
    trajectory as one whose start times are summed segment by segment, as the old ``finish`` did."""
    planner = _planned_tail(60)
    plan = planner.finish(START, [0.0] * 6, [0.0] * 6)
    segments = list(plan._trajs)
    starts = [0.0]
    for traj in segments[:-1]:
        starts.append(starts[-1] + float(traj.duration))
    summed = PlannedTrajectory(segments, starts)
    assert plan.duration == pytest.approx(summed.duration, abs=1e-9)
    assert plan.final_positions == summed.final_positions
    got: list[list[float]] = [[0.0] * 6 for _ in range(3)]
    want: list[list[float]] = [[0.0] * 6 for _ in range(3)]
    times = [k * plan.duration / 997 for k in range(998)] + starts + [s + 1e-6 for s in starts]
    for t in sorted(times):
        plan.sample(t, *got)
        summed.sample(t, *want)
        for g, w in zip(got, want, strict=True):
            assert g == pytest.approx(w, abs=1e-9)


def test_a_released_plan_loses_a_few_segments_a_call() -> None:
    planner = _planned_tail(100)
    plan = planner.finish(START, [0.0] * 6, [0.0] * 6)
    left = []
    while plan.release(30):
        left.append(len(plan._trajs))
    assert left == [70, 40, 10]
    assert plan._trajs == []
    assert plan._starts == []
    assert not plan.release(30)


@pytest.mark.parametrize("end", ["cancel", "succeed"])
def test_an_ended_long_goals_plan_is_freed_a_few_segments_a_tick(end: str) -> None:
    """Old code: the plan of a goal that ended was freed in the call that ended it (a cancel
    request, or the tick that reached the goal): ~1.5 ms for 5 000 points."""
    count = 3 * RELEASE_SEGMENTS + 5
    robot = SimRobot.create(UR10E_LIMITS, START)
    robot.controller.accept_trajectory("g1", UR_JOINTS, _ur_points(count), robot.state, robot.now)
    goal = robot.controller._goal
    assert goal is not None
    plan = goal.plan
    del goal
    if end == "cancel":
        robot.step()
        assert robot.controller.cancel("g1")
    else:
        assert robot.run_until_result("g1", 10_000).status is GoalStatus.SUCCEEDED
    segments = len(plan._trajs)
    assert segments == count  # not freed in the call that ended the goal
    while segments:
        robot.step()
        assert len(plan._trajs) == max(segments - RELEASE_SEGMENTS, 0)
        segments = len(plan._trajs)
    assert robot.controller._released == []


async def test_the_runtime_checks_a_long_trajectory_over_many_turns_of_the_loop(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """With no time allowed per slice, the runtime turns the loop after every few points checked.
    Old code: the check ran in a worker thread, one call the loop could not step."""
    monkeypatch.setattr(slicing, "PLANNING_SLICE_S", 0.0)
    turns = 0
    stop = asyncio.Event()

    async def probe() -> None:
        nonlocal turns
        while not stop.is_set():
            turns += 1
            await asyncio.sleep(0)

    controller = MotionController(UR10E_LIMITS, period=PERIOD)
    state = ready_state(UR_JOINTS, START)
    task = asyncio.ensure_future(probe())
    await asyncio.sleep(0)
    planner = await slicing.sliced(controller.check_trajectory(UR_JOINTS, _ur_points(400), state))
    stop.set()
    await task
    assert len(planner.points) == 400
    assert turns >= 400  # a step (about a point) per slice


async def test_the_runtime_frees_a_goals_points_over_many_turns_of_the_loop(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A goal's message points and planner are freed a few objects a turn, and what someone else
    still holds is only let go of. Old code: each was freed in one turn (~1 ms for 5 000 points)."""
    monkeypatch.setattr(slicing, "PLANNING_SLICE_S", 0.0)
    planner = _planned_tail(100)
    planner.finish(START, [0.0] * 6, [0.0] * 6)
    message_points = tuple(_ur_points(2000))
    kept = list(range(1000))
    held: list[object] = [message_points, kept, planner]
    del planner, message_points
    turns = 0
    stop = asyncio.Event()

    async def probe() -> None:
        nonlocal turns
        while not stop.is_set():
            turns += 1
            await asyncio.sleep(0)

    task = asyncio.ensure_future(probe())
    await asyncio.sleep(0)
    await slicing.release(held)
    stop.set()
    await task
    assert held == []
    assert kept == list(range(1000))  # held elsewhere too: let go of, not taken apart
    assert turns >= 2000 // slicing.RELEASE_ITEMS
