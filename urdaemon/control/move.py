"""A point-to-point move planned offline with ruckig: ending at rest, time-optimal or in exactly the
duration asked for, slowed by the velocity and acceleration scales."""

from __future__ import annotations

import math
from collections.abc import Sequence

from ruckig import Ruckig

from urdaemon.control.limits import check_finite, check_positions_within, check_scale
from urdaemon.control.planned_trajectory import PlannedTrajectory
from urdaemon.control.ruckig_calls import calculate, check_extrema, new_input
from urdaemon.control.trajectory import MAX_GOAL_TIME_S, TIMING_SLACK, check_start, snap
from urdaemon.errors import GoalRejected
from urdaemon.model import JointLimits

__all__ = ["plan_move"]


def _fmt(x: float) -> str:
    return f"{x:.6g}"


def plan_move(
    start_pos: Sequence[float],
    start_vel: Sequence[float],
    start_acc: Sequence[float],
    target: Sequence[float],
    limits: JointLimits,
    *,
    duration: float | None = None,
    velocity_scale: float = 1.0,
    acceleration_scale: float = 1.0,
) -> PlannedTrajectory:
    """Point-to-point move ending at rest: time-optimal, or exactly ``duration`` s if that is feasible."""
    # The scales shrink max_velocity and max_acceleration; jerk stays at its limit.
    check_scale("velocity_scale", velocity_scale)
    check_scale("acceleration_scale", acceleration_scale)
    if duration is not None and not (math.isfinite(duration) and duration > 0.0):
        raise GoalRejected(f"duration must be a finite number > 0, got {duration}")
    if duration is not None and duration > MAX_GOAL_TIME_S:
        raise GoalRejected(f"duration {_fmt(duration)} s exceeds the longest goal, {_fmt(MAX_GOAL_TIME_S)} s")
    n = limits.dof
    check_start(limits, start_pos, start_vel, start_acc)
    if len(target) != n:
        raise GoalRejected(f"target has {len(target)} values for {n} joints")
    check_finite("target", target, limits.names)
    check_positions_within(limits, target, "target")
    _check_move_time(limits, start_pos, target, velocity_scale, acceleration_scale)
    otg = Ruckig(n)
    inp = new_input(limits, velocity_scale, acceleration_scale)
    zeros = [0.0] * n
    inp.current_position = list(start_pos)
    inp.current_velocity = snap(start_vel, zeros)
    inp.current_acceleration = snap(start_acc, zeros)
    inp.target_position = list(target)
    if duration is not None:
        inp.minimum_duration = duration
    traj = calculate(otg, inp, "move")
    if duration is not None and traj.duration > duration + TIMING_SLACK:
        inp.minimum_duration = None
        fastest = calculate(otg, inp, "move").duration
        if fastest > duration:
            raise GoalRejected(f"move needs at least {_fmt(fastest)} s but duration is {_fmt(duration)} s")
        raise GoalRejected(
            f"move: exactly {_fmt(duration)} s is not feasible from the current velocity (the fastest is "
            f"{_fmt(fastest)} s, the next feasible above is {_fmt(traj.duration)} s)"
        )
    if traj.duration > MAX_GOAL_TIME_S:
        raise GoalRejected(
            f"move would take {_fmt(traj.duration)} s, longer than the longest goal, "
            f"{_fmt(MAX_GOAL_TIME_S)} s"
        )
    check_extrema(limits, traj, start_pos, "move")
    return PlannedTrajectory([traj], [0.0])


def _check_move_time(
    limits: JointLimits,
    start: Sequence[float],
    target: Sequence[float],
    velocity_scale: float,
    acceleration_scale: float,
) -> None:
    """Refuse a move whose scaled limits make it last longer than the longest goal (before ruckig,
    whose time range ends near 7 600 s and whose solver fails on numerically extreme limits)."""
    for i, name in enumerate(limits.names):
        distance = abs(target[i] - start[i])
        if distance == 0.0:
            continue
        # Lower bounds of a rest-to-rest move's time: at top speed all the way, or accelerating all the way.
        least = max(
            distance / (limits.max_velocity[i] * velocity_scale),
            2.0 * math.sqrt(distance / (limits.max_acceleration[i] * acceleration_scale)),
        )
        if least > MAX_GOAL_TIME_S:
            raise GoalRejected(
                f"move: at velocity_scale {_fmt(velocity_scale)} and acceleration_scale "
                f"{_fmt(acceleration_scale)} {name} would need at least {_fmt(least)} s, longer than the "
                f"longest goal, {_fmt(MAX_GOAL_TIME_S)} s"
            )
