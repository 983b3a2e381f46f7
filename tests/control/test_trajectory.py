"""Offline planning: multi-point trajectories and point-to-point moves."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from ruckig import InputParameter, Ruckig, RuckigError, Trajectory

from tests.helpers import Stepped
from urdaemon.control import TrajectoryPoint, plan_move, plan_trajectory
from urdaemon.control.planned_trajectory import PlannedTrajectory
from urdaemon.control.ruckig_calls import calculate, position_extrema
from urdaemon.errors import GoalRejected
from urdaemon.model import JointLimits

from .sim import THREE_LIMITS, UR10E_LIMITS

WIDE_LIMITS = JointLimits(
    names=("a", "b", "c"),
    min_position=(-3.0, -3.0, -3.0),
    max_position=(3.0, 3.0, 3.0),
    max_velocity=(2.0, 2.0, 2.0),
    max_acceleration=(5.0, 5.0, 5.0),
    max_jerk=(50.0, 50.0, 50.0),
)

Z3 = (0.0, 0.0, 0.0)
Z6 = (0.0,) * 6


def _sample(plan: PlannedTrajectory, t: float) -> tuple[list[float], list[float], list[float]]:
    n = len(plan.final_positions)
    pos, vel, acc = [0.0] * n, [0.0] * n, [0.0] * n
    plan.sample(t, pos, vel, acc)
    return pos, vel, acc


def _three_points() -> list[TrajectoryPoint]:
    return [
        TrajectoryPoint((0.3, 0.5, 0.1), 1.0),
        TrajectoryPoint((0.6, 0.8, -0.2), 2.0),
        TrajectoryPoint((0.2, 1.0, 0.0), 3.5),
    ]


def test_segment_times_are_met_exactly() -> None:
    points = _three_points()
    plan = plan_trajectory(Z3, Z3, Z3, points, THREE_LIMITS)
    assert plan.duration == pytest.approx(3.5, abs=1e-12)
    assert plan.segment_count == 3
    for pt in points:
        pos, _, _ = _sample(plan, pt.time_from_start)
        assert pos == pytest.approx(list(pt.positions), abs=1e-9)
    assert plan.final_positions == pytest.approx((0.2, 1.0, 0.0), abs=1e-12)
    _, vel, acc = _sample(plan, plan.duration)
    assert vel == pytest.approx([0.0] * 3, abs=1e-12)
    assert acc == pytest.approx([0.0] * 3, abs=1e-9)


def test_segments_join_continuously() -> None:
    plan = plan_trajectory(Z3, Z3, Z3, _three_points(), THREE_LIMITS)
    for boundary in (1.0, 2.0):
        p0, v0, a0 = _sample(plan, boundary - 1e-7)
        p1, v1, a1 = _sample(plan, boundary + 1e-7)
        assert p0 == pytest.approx(p1, abs=1e-6)
        assert v0 == pytest.approx(v1, abs=1e-4)
        assert a0 == pytest.approx(a1, abs=1e-3)


def test_turning_points_get_zero_velocity_and_monotone_ones_do_not() -> None:
    # Joint a turns at point 1 (0.3 → 0.6 → 0.2); joint b keeps rising through it.
    plan = plan_trajectory(Z3, Z3, Z3, _three_points(), THREE_LIMITS)
    _, vel, _ = _sample(plan, 2.0)
    assert vel[0] == pytest.approx(0.0, abs=1e-12)
    assert vel[1] > 0.0
    # Harmonic mean of the slopes 0.3 and 0.2/1.5 on either side.
    s_in, s_out = 0.3, 0.2 / 1.5
    assert vel[1] == pytest.approx(2 * s_in * s_out / (s_in + s_out))


def test_given_waypoint_velocities_and_accelerations_are_met() -> None:
    points = [
        TrajectoryPoint((0.4, 0.0, 0.0), 1.0, velocities=(0.5, 0.2, -0.1), accelerations=(0.0, 0.5, 0.0)),
        TrajectoryPoint((0.8, 0.4, -0.2), 2.0, velocities=(0.3, 0.0, 0.0)),
        TrajectoryPoint((0.9, 0.4, -0.2), 3.0),
    ]
    plan = plan_trajectory(Z3, Z3, Z3, points, THREE_LIMITS)
    _, vel, acc = _sample(plan, 1.0)
    assert vel == pytest.approx([0.5, 0.2, -0.1], abs=1e-9)
    assert acc == pytest.approx([0.0, 0.5, 0.0], abs=1e-9)
    _, vel, _ = _sample(plan, 2.0)
    assert vel == pytest.approx([0.3, 0.0, 0.0], abs=1e-9)
    assert plan.final_velocities == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)


@pytest.mark.parametrize("field", ["velocities", "accelerations"])
def test_a_trajectory_that_does_not_end_at_rest_is_rejected(field: str) -> None:
    moving = (0.3, 0.0, 0.0)
    last = (
        TrajectoryPoint((0.8, 0.0, 0.0), 2.0, velocities=moving)
        if field == "velocities"
        else TrajectoryPoint((0.8, 0.0, 0.0), 2.0, accelerations=moving)
    )
    points = [TrajectoryPoint((0.4, 0.0, 0.0), 1.0), last]
    with pytest.raises(GoalRejected, match=f"point 1: the last point's {field} must be zero"):
        plan_trajectory(Z3, Z3, Z3, points, THREE_LIMITS)


def test_starts_from_a_moving_state() -> None:
    plan = plan_trajectory((0.1, 0.0, 0.0), (0.5, 0.0, 0.0), (1.0, 0.0, 0.0), _three_points(), THREE_LIMITS)
    pos, vel, acc = _sample(plan, 0.0)
    assert pos == pytest.approx([0.1, 0.0, 0.0])
    assert vel == pytest.approx([0.5, 0.0, 0.0])
    assert acc == pytest.approx([1.0, 0.0, 0.0])


def test_sample_clamps_and_can_go_backwards() -> None:
    plan = plan_trajectory(Z3, Z3, Z3, _three_points(), THREE_LIMITS)
    end = _sample(plan, 99.0)
    assert end[0] == pytest.approx([0.2, 1.0, 0.0])
    mid = _sample(plan, 2.0)
    start = _sample(plan, -1.0)
    assert start[0] == pytest.approx([0.0, 0.0, 0.0])
    assert _sample(plan, 2.0) == mid


def test_infeasible_timing_is_rejected_with_the_minimum() -> None:
    # 1.5 rad on joint a needs 1.5/2 + 2/5 + 5/50 = 1.25 s from rest to rest.
    points = [TrajectoryPoint((1.0, 0.0, 0.0), 0.5)]
    with pytest.raises(GoalRejected) as info:
        plan_trajectory((-0.5, 0.0, 0.0), Z3, Z3, points, THREE_LIMITS)
    reason = info.value.reason
    assert reason.startswith("point 0: reaching it needs at least 1.25 s")
    assert "time_from_start allows 0.5 s" in reason


def test_infeasible_later_segment_is_named() -> None:
    points = [TrajectoryPoint((0.1, 0.0, 0.0), 1.0), TrajectoryPoint((0.9, 0.0, 0.0), 1.1)]
    with pytest.raises(GoalRejected, match=r"^point 1: reaching it needs at least .* allows 0.1 s"):
        plan_trajectory(Z3, Z3, Z3, points, THREE_LIMITS)


def test_timing_within_a_millisecond_is_accepted() -> None:
    points = [TrajectoryPoint((1.0, 0.0, 0.0), 1.2496)]
    plan = plan_trajectory((-0.5, 0.0, 0.0), Z3, Z3, points, THREE_LIMITS)
    assert plan.duration == pytest.approx(1.25)


def test_overshoot_beyond_a_limit_is_rejected() -> None:
    # Moving up at 2 rad/s 0.3 rad below the limit: braking needs 0.5 rad, so the segment overshoots.
    points = [TrajectoryPoint((0.71, 0.0, 0.0), 2.0)]
    with pytest.raises(GoalRejected) as info:
        plan_trajectory((0.7, 0.0, 0.0), (2.0, 0.0, 0.0), Z3, points, THREE_LIMITS)
    assert "point 0: a overshoots to 1.19" in info.value.reason
    assert "beyond its limit 1" in info.value.reason


def test_starting_outside_a_limit_may_move_back_in() -> None:
    plan = plan_trajectory((1.1, 0.0, 0.0), Z3, Z3, [TrajectoryPoint((0.9, 0.0, 0.0), 1.0)], THREE_LIMITS)
    assert plan.final_positions[0] == pytest.approx(0.9)


@pytest.mark.parametrize(
    ("points", "expected"),
    [
        ([], "the trajectory has no points"),
        ([TrajectoryPoint((0.1, 0.0, 0.0), 0.0)], "point 0: time_from_start must be > 0"),
        ([TrajectoryPoint((0.1, 0.0, 0.0), -1.0)], "point 0: time_from_start must be > 0"),
        (
            [TrajectoryPoint((0.1, 0.0, 0.0), 1.0), TrajectoryPoint((0.2, 0.0, 0.0), 1.0)],
            "point 1: time_from_start 1 s is not after point 0's 1 s",
        ),
        ([TrajectoryPoint((0.1, 0.0), 1.0)], "point 0: positions has 2 values for 3 joints"),
        ([TrajectoryPoint((0.1, math.nan, 0.0), 1.0)], "point 0 positions: b is nan"),
        ([TrajectoryPoint((0.1, 0.0, 0.0), math.inf)], "point 0: time_from_start is inf"),
        (
            [TrajectoryPoint((0.1, 0.0, 0.6), 1.0)],
            "point 0: c position 0.6 is outside its limits [-0.5, 0.5]",
        ),
        (
            [TrajectoryPoint((0.1, 0.0, 0.0), 1.0, velocities=(0.0, 1.6, 0.0)), TrajectoryPoint(Z3, 2.0)],
            "point 0: b velocity 1.6 exceeds its limit 1.5",
        ),
        (
            [TrajectoryPoint((0.1, 0.0, 0.0), 1.0, velocities=(0.0, 0.0))],
            "point 0: velocities has 2 values for 3 joints",
        ),
        (
            [TrajectoryPoint((0.1, 0.0, 0.0), 1.0, accelerations=(0.0, 0.0, 9.0))],
            "point 0: c acceleration 9 exceeds its limit 3",
        ),
    ],
)
def test_invalid_points_are_rejected_with_reason(points: list[TrajectoryPoint], expected: str) -> None:
    with pytest.raises(GoalRejected) as info:
        plan_trajectory(Z3, Z3, Z3, points, THREE_LIMITS)
    assert expected in info.value.reason


def test_invalid_start_state_is_rejected() -> None:
    with pytest.raises(GoalRejected, match="start velocity: a is nan"):
        plan_trajectory(Z3, (math.nan, 0.0, 0.0), Z3, _three_points(), THREE_LIMITS)
    with pytest.raises(GoalRejected, match="start position has 2 values for 3 joints"):
        plan_trajectory((0.0, 0.0), Z3, Z3, _three_points(), THREE_LIMITS)


def test_ruckig_refusal_becomes_goal_rejected() -> None:
    # Ruckig's own input validation (here a target velocity above the limit) is reported, not raised raw.
    inp = InputParameter(1)
    inp.current_position = [0.0]
    inp.target_position = [1.0]
    inp.target_velocity = [3.0]
    inp.max_velocity = [2.0]
    inp.max_acceleration = [5.0]
    inp.max_jerk = [50.0]
    with pytest.raises(GoalRejected, match=r"^point 7: .*target velocity") as info:
        calculate(Ruckig(1), inp, "point 7")
    assert isinstance(info.value.__cause__, RuckigError)


def test_six_joint_trajectory_within_limits() -> None:
    points = [
        TrajectoryPoint((0.5, -0.5, 1.0, 0.2, -0.3, 1.5), 2.0),
        TrajectoryPoint((1.0, -1.0, 2.0, 0.4, -0.6, 3.0), 4.0),
        TrajectoryPoint((0.0, 0.0, 0.0, 0.0, 0.0, 0.0), 7.0),
    ]
    plan = plan_trajectory(Z6, Z6, Z6, points, UR10E_LIMITS)
    assert plan.duration == pytest.approx(7.0)
    pos, vel, acc = [0.0] * 6, [0.0] * 6, [0.0] * 6
    for k in range(701):
        plan.sample(k * 0.01, pos, vel, acc)
        for i in range(6):
            assert abs(vel[i]) <= UR10E_LIMITS.max_velocity[i] + 1e-9
            assert abs(acc[i]) <= UR10E_LIMITS.max_acceleration[i] + 1e-9


# ------------------------------------------------------------------ moves


def test_move_is_time_optimal() -> None:
    # 3 rad at v=2, a=5, j=50 reaches every limit: T = d/v + v/a + a/j = 1.5 + 0.4 + 0.1.
    plan = plan_move((-1.5, 0.0, 0.0), Z3, Z3, (1.5, 0.0, 0.0), WIDE_LIMITS)
    assert plan.duration == pytest.approx(2.0, abs=1e-9)
    assert plan.final_positions == pytest.approx((1.5, 0.0, 0.0))
    _, vel, _ = _sample(plan, 1.0)
    assert vel[0] == pytest.approx(2.0)


def test_move_synchronizes_joints() -> None:
    plan = plan_move((-1.5, 0.0, 0.0), Z3, Z3, (1.5, 0.5, -0.2), WIDE_LIMITS)
    assert plan.duration == pytest.approx(2.0, abs=1e-9)
    # Every joint is still moving halfway and arrives together.
    _, vel, _ = _sample(plan, 1.0)
    assert all(abs(v) > 0.0 for v in vel)
    assert _sample(plan, 2.0)[0] == pytest.approx([1.5, 0.5, -0.2])


def test_move_with_duration_takes_exactly_that_long() -> None:
    plan = plan_move((-1.5, 0.0, 0.0), Z3, Z3, (1.5, 0.0, 0.0), WIDE_LIMITS, duration=3.25)
    assert plan.duration == 3.25
    assert _sample(plan, 3.25)[0] == pytest.approx([1.5, 0.0, 0.0])


def test_move_with_too_short_duration_names_the_minimum() -> None:
    with pytest.raises(GoalRejected) as info:
        plan_move((-1.5, 0.0, 0.0), Z3, Z3, (1.5, 0.0, 0.0), WIDE_LIMITS, duration=1.5)
    assert info.value.reason == "move needs at least 2 s but duration is 1.5 s"


@pytest.mark.parametrize(
    ("velocity_scale", "acceleration_scale", "expected"),
    [
        (0.5, 1.0, 3.0 + 0.2 + 0.1),  # v=1: 3/1 + 1/5 + 5/50
        (1.0, 0.5, 1.5 + 0.8 + 0.05),  # a=2.5: 3/2 + 2/2.5 + 2.5/50
        (0.5, 0.5, 3.0 + 0.4 + 0.05),  # v=1, a=2.5
    ],
)
def test_move_scales_limit_velocity_and_acceleration(
    velocity_scale: float, acceleration_scale: float, expected: float
) -> None:
    plan = plan_move(
        (-1.5, 0.0, 0.0),
        Z3,
        Z3,
        (1.5, 0.0, 0.0),
        WIDE_LIMITS,
        velocity_scale=velocity_scale,
        acceleration_scale=acceleration_scale,
    )
    assert plan.duration == pytest.approx(expected, abs=1e-9)
    worst_v = worst_a = 0.0
    for k in range(int(expected / 0.01) + 1):
        _, vel, acc = _sample(plan, k * 0.01)
        worst_v = max(worst_v, abs(vel[0]))
        worst_a = max(worst_a, abs(acc[0]))
    assert worst_v <= 2.0 * velocity_scale + 1e-9
    assert worst_a <= 5.0 * acceleration_scale + 1e-9


def test_move_to_where_it_is_takes_no_time() -> None:
    plan = plan_move((0.2, 0.1, 0.0), Z3, Z3, (0.2, 0.1, 0.0), THREE_LIMITS)
    assert plan.duration == 0.0
    assert _sample(plan, 0.0)[0] == pytest.approx([0.2, 0.1, 0.0])


@pytest.mark.parametrize(
    ("kwargs", "target", "expected"),
    [
        ({"velocity_scale": 0.0}, (0.1, 0.0, 0.0), "velocity_scale must be in (0, 1], got 0.0"),
        ({"velocity_scale": 1.5}, (0.1, 0.0, 0.0), "velocity_scale must be in (0, 1], got 1.5"),
        ({"acceleration_scale": math.nan}, (0.1, 0.0, 0.0), "acceleration_scale must be in (0, 1], got nan"),
        ({"duration": 0.0}, (0.1, 0.0, 0.0), "duration must be a finite number > 0, got 0.0"),
        ({"duration": -2.0}, (0.1, 0.0, 0.0), "duration must be a finite number > 0, got -2.0"),
        ({}, (0.1, 0.0, 2.0), "target: c position 2 is outside its limits [-0.5, 0.5]"),
        ({}, (0.1, math.inf, 0.0), "target: b is inf"),
        ({}, (0.1, 0.0), "target has 2 values for 3 joints"),
    ],
)
def test_move_rejections(kwargs: dict[str, float], target: tuple[float, ...], expected: str) -> None:
    with pytest.raises(GoalRejected) as info:
        plan_move(Z3, Z3, Z3, target, THREE_LIMITS, **kwargs)
    assert expected in info.value.reason


def test_move_overshoot_beyond_a_limit_is_rejected() -> None:
    with pytest.raises(GoalRejected, match=r"^move: a overshoots to 1\.19\d*, beyond its limit 1$"):
        plan_move((0.7, 0.0, 0.0), (2.0, 0.0, 0.0), Z3, (0.71, 0.0, 0.0), THREE_LIMITS)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    p0=st.floats(-1.0, 1.0),
    v0=st.floats(-3.0, 3.0),
    a0=st.floats(-8.0, 8.0),
    target=st.floats(-1.0, 1.0),
    target_v=st.floats(-1.9, 1.9),
)
def test_position_extrema_match_dense_sampling(
    p0: float, v0: float, a0: float, target: float, target_v: float
) -> None:
    # Start states beyond the limits (brake profiles) are included on purpose.
    inp = InputParameter(1)
    inp.current_position = [p0]
    inp.current_velocity = [v0]
    inp.current_acceleration = [a0]
    inp.target_position = [target]
    inp.target_velocity = [target_v]
    inp.max_velocity = [2.0]
    inp.max_acceleration = [5.0]
    inp.max_jerk = [50.0]
    traj = Trajectory(1)
    Ruckig(1).calculate(inp, traj)
    steps = 4000
    samples = [traj.at_time(traj.duration * k / steps)[0][0] for k in range(steps + 1)]
    ((lo, hi),) = position_extrema(traj)
    # The analytic extrema enclose every sample and are attained up to the sampling resolution.
    assert lo <= min(samples) + 1e-9
    assert hi >= max(samples) - 1e-9
    resolution = 3.0 * traj.duration / steps + 1e-9
    assert lo >= min(samples) - resolution
    assert hi <= max(samples) + resolution


def test_degenerate_rest_to_rest_move_that_trips_ruckig_is_planned() -> None:
    """−1.4 → −1.5 at a = 5, j = 50 is exactly 2·a³/j²: plain ruckig 0.19.4 throws on it."""
    from urdaemon.control.move import plan_move
    from urdaemon.model import JointLimits

    limits = JointLimits(
        names=("j",),
        min_position=(-6.0,),
        max_position=(6.0,),
        max_velocity=(3.141592653589793,),
        max_acceleration=(5.0,),
        max_jerk=(50.0,),
    )
    plan = plan_move([-1.4], [0.0], [0.0], [-1.5], limits)
    assert plan.final_positions[0] == pytest.approx(-1.5, abs=1e-9)
    pos, vel, acc = [0.0], [0.0], [0.0]
    plan.sample(plan.duration, pos, vel, acc)
    assert pos[0] == pytest.approx(-1.5, abs=1e-9)
    steps = int(plan.duration / 0.002) + 1
    for k in range(steps):
        plan.sample(k * 0.002, pos, vel, acc)
        assert abs(vel[0]) <= 3.141592653589793
        assert abs(acc[0]) <= 5.0 + 1e-9


def _dense_points(n: int) -> list[TrajectoryPoint]:
    """A smooth 6-joint sine trajectory with velocities and accelerations, 50 ms apart, ending at rest."""
    w, amp, dt = 0.5, 0.3, 0.05
    points = [
        TrajectoryPoint(
            positions=tuple(amp * math.sin(w * t + j) - amp * math.sin(j) for j in range(6)),
            velocities=tuple(amp * w * math.cos(w * t + j) for j in range(6)),
            accelerations=tuple(-amp * w * w * math.sin(w * t + j) for j in range(6)),
            time_from_start=t,
        )
        for t in (dt * (k + 1) for k in range(n - 1))
    ]
    return [*points, TrajectoryPoint(points[-1].positions, points[-1].time_from_start + 1.0)]


def test_stepwise_planning_equals_one_shot_planning(monkeypatch: pytest.MonkeyPatch) -> None:
    from urdaemon.control import trajectory
    from urdaemon.control.trajectory import TrajectoryPlanner

    points = _dense_points(40)
    start_v = [0.3 * 0.5 * math.cos(j) for j in range(6)]
    start_a = [0.0] * 6
    whole = plan_trajectory([0.0] * 6, start_v, start_a, points, UR10E_LIMITS)
    planner = TrajectoryPlanner(points, UR10E_LIMITS, [0.0] * 6)
    tail = Stepped(planner.tail_steps())
    steps = 0
    for _ in range(len(points) + 1):
        steps += 1
        if not tail.step():
            break
    assert steps == len(points) - 1, "one step per tail segment"
    assert tail.step() is False
    calls: list[str] = []

    def counted(otg: Ruckig, inp: InputParameter, what: str) -> Trajectory:
        calls.append(what)
        return calculate(otg, inp, what)

    monkeypatch.setattr(trajectory, "calculate", counted)
    stepped = planner.finish([0.0] * 6, start_v, start_a)
    monkeypatch.undo()
    assert calls == ["point 0"], "the whole tail was planned in the steps: finish plans segment 0 only"
    assert stepped.duration == pytest.approx(whole.duration, abs=1e-12)
    assert stepped.segment_count == whole.segment_count == len(points)
    for k in range(1001):
        t = whole.duration * k / 1000
        for a, b in zip(_sample(stepped, t), _sample(whole, t), strict=True):
            assert a == pytest.approx(b, abs=1e-9)


def test_a_prepared_tail_joins_a_start_that_moved_while_it_was_planned() -> None:
    from urdaemon.control.trajectory import TrajectoryPlanner

    # the first point one second out, so that segment 0 has time to absorb a different start
    points = [
        TrajectoryPoint(pt.positions, pt.time_from_start + 1.0, pt.velocities, pt.accelerations)
        for pt in _dense_points(20)
    ]
    planner = TrajectoryPlanner(points, UR10E_LIMITS, [0.0] * 6)
    for _ in planner.tail_steps():
        pass
    # the robot drifted a little (a preempted motion went on) before the goal was committed
    start = [0.001 * (j + 1) for j in range(6)]
    plan = planner.finish(start, [0.01] * 6, [0.0] * 6)
    assert _sample(plan, 0.0)[0] == pytest.approx(start, abs=1e-12)
    for k, pt in enumerate(points):
        position = _sample(plan, pt.time_from_start)[0]
        assert position == pytest.approx(list(pt.positions), abs=1e-9), f"point {k}"


def test_infeasible_tail_segment_is_rejected_while_planning_the_tail() -> None:
    from urdaemon.control.trajectory import TrajectoryPlanner

    points = [
        TrajectoryPoint(positions=(0.1, 0.0, 0.0), time_from_start=1.0),
        TrajectoryPoint(positions=(0.9, 0.0, 0.0), time_from_start=1.05),
    ]
    planner = TrajectoryPlanner(points, THREE_LIMITS, [0.0] * 3)
    with pytest.raises(GoalRejected, match="point 1: reaching it needs at least"):
        next(planner.tail_steps())
