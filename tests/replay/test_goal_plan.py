"""goal_plan.py from tables and generated motions: recorded samples made from the controller's own
jerk-limited moves (control/move.py, sampled every cycle as the mock publishes them, with the
host times jittered), planned into goals, and the goals planned again by the controller's planner:
every recorded position comes back at its recorded time ÷ rate.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from urdaemon.control.goal_types import TrajectoryPoint
from urdaemon.control.move import plan_move
from urdaemon.control.trajectory import plan_trajectory
from urdaemon.model import JointLimits
from urdaemon.replay.goal_plan import (
    Plan,
    Sample,
    Step,
    Track,
    estimate_accelerations,
    make_plan,
    sample_ticks,
    unplanned_motion,
)

DOF = 6
P = 0.002
T0 = 1_700_000_000_000_000_000
LIMITS = JointLimits(
    tuple(f"j{i}" for i in range(DOF)),
    (-6.28,) * DOF,
    (6.28,) * DOF,
    (2.0,) * DOF,
    (5.0,) * DOF,
    (50.0,) * DOF,
)
HOME = (0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0)
ZEROS = [0.0] * DOF


def _record(
    targets: Sequence[Sequence[float]], rests: Sequence[int], start: Sequence[float] = HOME
) -> list[tuple[int, tuple[float, ...], tuple[float, ...], tuple[float, ...]]]:
    """(tick, positions, velocities, accelerations) every cycle: a rest of ``rests[0]`` ticks, then
    each move (time-optimal, as a move goal) followed by its rest."""
    out: list[tuple[int, tuple[float, ...], tuple[float, ...], tuple[float, ...]]] = []
    tick, position = 0, list(start)
    for _ in range(rests[0]):
        out.append((tick, tuple(position), tuple(ZEROS), tuple(ZEROS)))
        tick += 1
    for target, rest in zip(targets, rests[1:], strict=True):
        plan = plan_move(position, ZEROS, ZEROS, list(target), LIMITS)
        k = 1
        while (k - 1) * P <= plan.duration:
            p, v, a = [0.0] * DOF, [0.0] * DOF, [0.0] * DOF
            plan.sample(k * P, p, v, a)
            out.append((tick, tuple(p), tuple(v), tuple(a)))
            tick, k = tick + 1, k + 1
        position = list(plan.final_positions)
        for _ in range(rest):
            out.append((tick, tuple(position), tuple(ZEROS), tuple(ZEROS)))
            tick += 1
    return out


def _samples(recorded: Sequence[Any], seed: int, jitter_ns: int = 900_000) -> tuple[Sample, ...]:
    rng = random.Random(seed)
    return tuple(Sample(T0 + round(t * P * 1e9) + rng.randrange(jitter_ns), p, v) for t, p, v, _ in recorded)


def _replay_error(recorded: Sequence[Any], rate: float, seed: int = 0) -> tuple[float, int]:
    """Plan the recording, plan each goal as the controller does, sample it on the replay's cycles;
    the largest error at a recorded sample (offset ÷ rate) and how many were compared."""
    plan = make_plan([Track("alice", P, _samples(recorded, seed))], rate)
    position = list(plan.first["alice"])
    worst, compared = 0.0, 0
    for step in plan.steps:
        points = [
            TrajectoryPoint(
                tuple(p["positions"]), p["time_from_start"], tuple(p["velocities"]), tuple(p["accelerations"])
            )
            for p in step.parts["alice"]
        ]
        replay = plan_trajectory(position, ZEROS, ZEROS, points, LIMITS)
        start = round(step.start_s / P)
        for tick, p, _, _ in recorded:
            m = (tick - start) / rate
            if m < 0 or abs(m - round(m)) > 1e-9 or round(m) * P > replay.duration + 1e-9:
                continue
            q, w, a = [0.0] * DOF, [0.0] * DOF, [0.0] * DOF
            replay.sample(round(m) * P, q, w, a)
            worst = max(worst, max(abs(x - y) for x, y in zip(q, p, strict=True)))
            compared += 1
        position = list(replay.final_positions)
    return worst, compared


TWO_MOVES = ([[0.5, -1.2, 1.2, -1.5, -1.5, 0.3], [0.1, -1.4, 1.3, -1.2, -1.5, 0.0]], [20, 30, 20])


@pytest.mark.parametrize("rate", [1.0, 0.5, 0.25])
def test_two_moves_come_back_at_their_recorded_times(rate: float) -> None:
    recorded = _record(*TWO_MOVES)
    worst, compared = _replay_error(recorded, rate)
    assert compared >= len(recorded) * (0.9 if rate == 1.0 else 0.85)
    assert worst < 1e-9


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    targets=st.lists(
        st.lists(st.floats(-1.0, 1.0), min_size=DOF, max_size=DOF).map(
            lambda d: [h + x for h, x in zip(HOME, d, strict=True)]
        ),
        min_size=1,
        max_size=2,
    ),
    rest=st.integers(2, 40),
    rate=st.sampled_from([1.0, 0.5]),
    seed=st.integers(0, 1000),
)
def test_any_sequence_of_moves_comes_back(
    targets: list[list[float]], rest: int, rate: float, seed: int
) -> None:
    recorded = _record(targets, [rest] * (len(targets) + 1))
    if not any(any(v) for _, _, v, _ in recorded):
        return
    worst, compared = _replay_error(recorded, rate, seed)
    assert compared > 0
    assert worst < 1e-7  # the acceptance bound is 1e-6


def test_ticks_follow_the_motion_not_the_host_clock() -> None:
    """Host times jittered by up to 1.8 ms and a 40 ms stall (the daemon's loop held up, cycles
    missed) in the middle of a move: every moving interval is still one tick."""
    recorded = _record([TWO_MOVES[0][0]], [5, 5])
    samples = list(_samples(recorded, 3, jitter_ns=1_800_000))
    middle = len(samples) // 2
    for k in range(middle, len(samples)):
        s = samples[k]
        samples[k] = Sample(s.time_ns + 40_000_000, s.positions, s.velocities)
    ticks = sample_ticks(samples, P)
    moving = [
        k for k in range(1, len(samples)) if any(samples[k].velocities) or any(samples[k - 1].velocities)
    ]
    assert {ticks[k] - ticks[k - 1] for k in moving} == {1}


@pytest.mark.parametrize(
    ("gaps_ns", "ticks"),
    [
        ([2_000_000, 2_000_000], [0, 1, 2]),
        ([2_900_000, 1_100_000], [0, 1, 2]),
        ([6_100_000], [0, 3]),
        ([100_000], [0, 1]),
    ],
)
def test_at_rest_the_host_time_decides(gaps_ns: list[int], ticks: list[int]) -> None:
    times = [T0]
    for gap in gaps_ns:
        times.append(times[-1] + gap)
    samples = [Sample(t, HOME, tuple(ZEROS)) for t in times]
    assert sample_ticks(samples, P) == ticks


def test_accelerations_are_the_motions_own_but_where_jerk_switches() -> None:
    recorded = _record([TWO_MOVES[0][0]], [3, 3])
    times = [t * P for t, _, _, _ in recorded]
    found = estimate_accelerations(times, [p for _, p, _, _ in recorded], [v for _, _, v, _ in recorded])
    errors = [
        max(abs(x - y) for x, y in zip(f, a, strict=True))
        for f, (_, _, _, a) in zip(found, recorded, strict=True)
    ]
    assert max(errors) < 1e-6


def test_a_motion_longer_than_one_goal_is_cut_where_every_robot_rests(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """At half rate every sample is a point: six moves of about 0.35 s at 500 Hz do not fit in a
    goal of (here) 500 points, so they are cut at rests; no piece holds more than a goal may."""
    monkeypatch.setattr("urdaemon.replay.goal_plan.MAX_POINTS", 500)
    targets = [[0.2, -1.4, 1.4, -1.5, -1.5, 0.1], list(HOME)] * 3
    recorded = _record(targets, [5] * (len(targets) + 1))
    plan = make_plan([Track("alice", P, _samples(recorded, 1))], 0.5)
    assert len(plan.steps) >= 2
    assert all(len(step.parts["alice"]) <= 500 for step in plan.steps)
    for step in plan.steps:
        last = step.parts["alice"][-1]
        assert not any(last["velocities"])
        assert not any(last["accelerations"])
    assert plan.notes == []
    worst, compared = _replay_error(recorded, 0.5)
    assert worst < 1e-7  # the acceptance bound is 1e-6
    assert compared > len(recorded)


def test_a_stretch_that_cannot_fit_is_thinned_and_said(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("urdaemon.replay.goal_plan.MAX_POINTS", 100)
    recorded = _record([[0.5, -1.2, 1.2, -1.5, -1.5, 0.3]], [5, 5])
    plan = make_plan([Track("alice", P, _samples(recorded, 2))], 0.5)
    assert len(plan.steps) == 1
    assert len(plan.steps[0].parts["alice"]) <= 100
    assert any("does not fit in one goal" in note for note in plan.notes)


def test_what_moves_before_the_first_rest_or_after_the_last_is_left_out_and_said() -> None:
    recorded = _record(*TWO_MOVES)
    samples = _samples(recorded, 4)
    moving_at_both_ends = samples[25:-25]
    plan = make_plan([Track("alice", P, moving_at_both_ends)], 1.0)
    assert any("moving when the recording starts" in n for n in plan.notes)
    assert any("moving when the recording ends" in n for n in plan.notes)
    assert plan.first["alice"] != HOME


def test_a_robot_resting_throughout_gets_no_part() -> None:
    recorded = _record(*TWO_MOVES)
    still = tuple(Sample(s.time_ns, HOME, tuple(ZEROS)) for s in _samples(recorded, 5))
    plan = make_plan([Track("alice", P, _samples(recorded, 5)), Track("bob", 0.008, still[::4])], 1.0)
    assert plan.steps
    assert all(set(step.parts) == {"alice"} for step in plan.steps)


@pytest.mark.parametrize("rate", [0.0, -1.0, math.inf, math.nan])
def test_a_rate_that_is_not_a_positive_number_is_refused(rate: float) -> None:
    with pytest.raises(ValueError, match="rate must be"):
        make_plan([], rate)


def test_at_the_recorded_speed_every_sample_as_a_point_is_refused_by_the_controller() -> None:
    """Why ``moves`` from rate 1 up: the recorded states lie on the jerk limits' boundary, and the
    controller's planner refuses them as points at the recorded timing."""
    from urdaemon.errors import GoalRejected

    recorded = _record(*TWO_MOVES)
    plan = make_plan([Track("alice", P, _samples(recorded, 6))], 1.0, "samples")
    points = [
        TrajectoryPoint(
            tuple(p["positions"]), p["time_from_start"], tuple(p["velocities"]), tuple(p["accelerations"])
        )
        for p in plan.steps[0].parts["alice"]
    ]
    with pytest.raises(GoalRejected, match="reaching it needs at least"):
        plan_trajectory(list(plan.first["alice"]), ZEROS, ZEROS, points, LIMITS)


def test_moves_below_rate_1_keep_the_rests_and_stretch_the_moves() -> None:
    recorded = _record(*TWO_MOVES)
    plan = make_plan([Track("alice", P, _samples(recorded, 7))], 0.5, "moves")
    part = plan.steps[0].parts["alice"]
    assert all(not any(p["velocities"]) for p in part)
    fast = make_plan([Track("alice", P, _samples(recorded, 7))], 1.0)
    assert [p["time_from_start"] for p in part] == pytest.approx(
        [2 * p["time_from_start"] for p in fast.steps[0].parts["alice"]]
    )


def test_an_unknown_mode_is_refused() -> None:
    with pytest.raises(ValueError, match="mode must be one of samples, moves"):
        make_plan([], 1.0, "splines")


@pytest.mark.parametrize(
    ("duration", "used"),
    [(0.70, True), (0.50, False), (1.0, False)],
)
def test_a_move_is_timed_by_the_goal_that_made_it_when_it_fits(duration: float, used: bool) -> None:
    """A measured arm's move lasts longer than it was planned: the recorded result of the goal that
    ended it (within 20 % of the measured duration) times it instead."""
    recorded = _record([TWO_MOVES[0][0]], [10, 10])
    samples = _samples(recorded, 8)
    measured = make_plan([Track("alice", P, samples)], 1.0).steps[0].parts["alice"]
    moving = [p["time_from_start"] for p in measured]
    ended = samples[-5].time_ns
    timed = make_plan([Track("alice", P, samples, ((ended, duration),))], 1.0).steps[0].parts["alice"]
    times = [p["time_from_start"] for p in timed]
    assert times[0] == moving[0]
    if used:
        assert times[1] - times[0] == pytest.approx(duration)
    else:
        assert times == moving


def test_a_recorded_motion_no_cell_goal_drives_is_named() -> None:
    """Issue 32: under load a replay played only the move to the start (0 cell goals) and exited 0;
    the robots whose recording moves but that no goal drives are named (drive.py then exits 1)."""
    moving = (
        Sample(T0, HOME, tuple(ZEROS)),
        Sample(T0 + 2_000_000, HOME, (0.1, 0, 0, 0, 0, 0)),
        Sample(T0 + 4_000_000, HOME, tuple(ZEROS)),
    )
    resting = (Sample(T0, HOME, tuple(ZEROS)), Sample(T0 + 2_000_000, HOME, tuple(ZEROS)))
    tracks = [Track("alice", P, moving), Track("bob", P, resting)]
    empty = Plan({"alice": HOME}, [], "samples")
    assert unplanned_motion(tracks, empty) == ["alice"]  # bob rests: nothing to replay is no error
    driven = Plan({"alice": HOME}, [Step(0.0, 1.0, {"alice": []})], "samples")
    assert unplanned_motion(tracks, driven) == []
