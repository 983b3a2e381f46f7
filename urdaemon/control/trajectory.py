"""Jerk-limited offline planning of multi-point trajectories with ruckig (point-to-point moves: move.py).

Ruckig's community build cannot plan through intermediate waypoints, so a trajectory is a chain of
state-to-state segments, each stretched to the client's timing with ``minimum_duration``. The community
build also ignores position limits, so every segment's position extrema are recomputed and checked
(ruckig_calls.py). The points are checked first, in steps (``check_points``, a generator of steps).
"""

from __future__ import annotations

import math
from collections.abc import Generator, Sequence
from typing import Any, TypeVar

from ruckig import Ruckig

from urdaemon.control.goal_types import TrajectoryPoint
from urdaemon.control.limits import (
    check_accelerations_within,
    check_finite,
    check_positions_within,
    check_velocities_within,
)
from urdaemon.control.planned_trajectory import PlannedTrajectory
from urdaemon.control.ruckig_calls import calculate, check_extrema, new_input
from urdaemon.errors import GoalRejected
from urdaemon.model import JointLimits

__all__ = [
    "MAX_GOAL_TIME_S",
    "SNAP_TOLERANCE",
    "TIMING_SLACK",
    "WAYPOINT_VELOCITY_FRACTION",
    "TrajectoryPlanner",
    "check_points",
    "check_start",
    "plan_trajectory",
    "snap",
]

TIMING_SLACK = 1e-3
"""A segment may take this much longer (s) than the client's timing before the goal is rejected."""

MAX_GOAL_TIME_S = 7200.0
"""Longest goal accepted (s); ruckig's time range ends near 7 600 s."""

WAYPOINT_VELOCITY_FRACTION = 0.9
"""Chosen waypoint velocities stay within this fraction of max_velocity, leaving room to correct."""

_T = TypeVar("_T")


def _fmt(x: float) -> str:
    return f"{x:.6g}"


def check_start(
    limits: JointLimits, start_pos: Sequence[float], start_vel: Sequence[float], start_acc: Sequence[float]
) -> None:
    """Refuse a start state (GoalRejected) whose lengths are not the joints' or whose values are not
    finite."""
    n = limits.dof
    for label, values in (
        ("start position", start_pos),
        ("start velocity", start_vel),
        ("start acceleration", start_acc),
    ):
        if len(values) != n:
            raise GoalRejected(f"{label} has {len(values)} values for {n} joints")
        check_finite(label, values, limits.names)


def _boundary_states(
    limits: JointLimits, start_pos: Sequence[float], points: Sequence[TrajectoryPoint]
) -> Generator[None, None, tuple[list[tuple[float, ...]], list[tuple[float, ...]]]]:
    """Velocity and acceleration at each point, one point a step: the client's, else for velocities
    a monotone-preserving estimate (0 at the last), for accelerations 0."""
    n = limits.dof
    zeros = (0.0,) * n
    velocities: list[tuple[float, ...]] = []
    accelerations: list[tuple[float, ...]] = []
    last = len(points) - 1
    for k, pt in enumerate(points):
        accelerations.append(zeros if pt.accelerations is None else tuple(pt.accelerations))
        if pt.velocities is not None:
            velocities.append(tuple(pt.velocities))
        elif k == last:
            velocities.append(zeros)
        else:
            prev = None if k == 0 else points[k - 1]
            velocities.append(_waypoint_velocity(limits, start_pos, prev, pt, points[k + 1]))
        yield
    return velocities, accelerations


def _waypoint_velocity(
    limits: JointLimits,
    start_pos: Sequence[float],
    prev: TrajectoryPoint | None,
    pt: TrajectoryPoint,
    nxt: TrajectoryPoint,
) -> tuple[float, ...]:
    """A monotone-preserving velocity at ``pt`` between ``prev`` (None: the start) and ``nxt``."""
    prev_pos = start_pos if prev is None else prev.positions
    prev_t = 0.0 if prev is None else prev.time_from_start
    dt_in = pt.time_from_start - prev_t
    dt_out = nxt.time_from_start - pt.time_from_start
    vel: list[float] = []
    for i in range(limits.dof):
        s_in = (pt.positions[i] - prev_pos[i]) / dt_in
        s_out = (nxt.positions[i] - pt.positions[i]) / dt_out
        if s_in * s_out <= 0.0:
            # A turning point (or a flat side): stopping there cannot overshoot it.
            vel.append(0.0)
            continue
        # Harmonic mean: leans toward the slower side, so a short slow segment is not overshot.
        v = 2.0 * s_in * s_out / (s_in + s_out)
        cap = WAYPOINT_VELOCITY_FRACTION * limits.max_velocity[i]
        vel.append(max(-cap, min(cap, v)))
    return tuple(vel)


def _validate_points(limits: JointLimits, points: Sequence[TrajectoryPoint]) -> Generator[None, None, None]:
    """Check every point, one a step; GoalRejected names the first fault."""
    if not points:
        raise GoalRejected("the trajectory has no points")
    prev_t = 0.0
    for k, pt in enumerate(points):
        _validate_point(limits, k, pt, prev_t)
        prev_t = pt.time_from_start
        yield
    last = points[-1]
    # A goal ends at rest: a final velocity would need an unplanned stop after the goal, which could
    # leave the joint limits and which a lagging robot would execute as stop-and-go.
    for label, values in (("velocities", last.velocities), ("accelerations", last.accelerations)):
        if values is not None and any(v != 0.0 for v in values if math.isfinite(v)):
            raise GoalRejected(
                f"point {len(points) - 1}: the last point's {label} must be zero (a trajectory ends at rest)"
            )


def _validate_point(limits: JointLimits, k: int, pt: TrajectoryPoint, prev_t: float) -> None:
    """Check point ``k`` (``prev_t``: the time_from_start of the point before it)."""
    n = limits.dof
    what = f"point {k}"
    if len(pt.positions) != n:
        raise GoalRejected(f"{what}: positions has {len(pt.positions)} values for {n} joints")
    check_finite(f"{what} positions", pt.positions, limits.names)
    if not math.isfinite(pt.time_from_start):
        raise GoalRejected(f"{what}: time_from_start is {pt.time_from_start}, not a finite number")
    if pt.time_from_start > MAX_GOAL_TIME_S:
        raise GoalRejected(
            f"{what}: time_from_start {_fmt(pt.time_from_start)} s exceeds the longest goal, "
            f"{_fmt(MAX_GOAL_TIME_S)} s"
        )
    if k == 0 and pt.time_from_start <= 0.0:
        raise GoalRejected(
            f"{what}: time_from_start must be > 0 (time from the goal's start), got {pt.time_from_start}"
        )
    if k > 0 and pt.time_from_start <= prev_t:
        raise GoalRejected(
            f"{what}: time_from_start {_fmt(pt.time_from_start)} s is not after point {k - 1}'s "
            f"{_fmt(prev_t)} s; times must strictly increase"
        )
    check_positions_within(limits, pt.positions, what)
    if pt.velocities is not None:
        if len(pt.velocities) != n:
            raise GoalRejected(f"{what}: velocities has {len(pt.velocities)} values for {n} joints")
        check_finite(f"{what} velocities", pt.velocities, limits.names)
        check_velocities_within(limits, pt.velocities, what)
    if pt.accelerations is not None:
        if len(pt.accelerations) != n:
            raise GoalRejected(f"{what}: accelerations has {len(pt.accelerations)} values for {n} joints")
        check_finite(f"{what} accelerations", pt.accelerations, limits.names)
        check_accelerations_within(limits, pt.accelerations, what)


def check_points(
    points: Sequence[TrajectoryPoint], limits: JointLimits, start_pos: Sequence[float]
) -> Generator[None, None, TrajectoryPlanner]:
    """Check a trajectory's points one step at a time (a few µs each); returns their planner.

    Raises GoalRejected naming the first fault, as ``TrajectoryPlanner(points, ...)`` does at once.
    """
    points = tuple(points)
    yield from _validate_points(limits, points)
    velocities, accelerations = yield from _boundary_states(limits, start_pos, points)
    return TrajectoryPlanner._checked(points, limits, velocities, accelerations)


def _run(steps: Generator[None, None, _T]) -> _T:
    """Every step at once; the return value."""
    while True:
        try:
            next(steps)
        except StopIteration as stop:
            return stop.value  # type: ignore[no-any-return]


class TrajectoryPlanner:
    """Plans a multi-point trajectory in steps, so a long one never stalls the caller's loop.

    Segment k ≥ 1 starts exactly at point k−1's target state (position, chosen velocity,
    acceleration), so the whole tail can be planned ahead, a segment per step (``tail_steps()``), before
    the robot's live state is known; ``finish(start)`` then plans only segment 0 from it. Each
    tail segment's start time is kept as it is planned, counted from the end of segment 0, so
    ``finish`` hands the plan over without walking the segments.
    """

    def __init__(
        self, points: Sequence[TrajectoryPoint], limits: JointLimits, start_pos: Sequence[float]
    ) -> None:
        """Check the points at once (``check_points`` does it in steps); GoalRejected names a fault."""
        points = tuple(points)
        _run(_validate_points(limits, points))
        velocities, accelerations = _run(_boundary_states(limits, start_pos, points))
        self._init(points, limits, velocities, accelerations)

    @classmethod
    def _checked(
        cls,
        points: tuple[TrajectoryPoint, ...],
        limits: JointLimits,
        velocities: list[tuple[float, ...]],
        accelerations: list[tuple[float, ...]],
    ) -> TrajectoryPlanner:
        planner = cls.__new__(cls)
        planner._init(points, limits, velocities, accelerations)
        return planner

    def _init(
        self,
        points: tuple[TrajectoryPoint, ...],
        limits: JointLimits,
        velocities: list[tuple[float, ...]],
        accelerations: list[tuple[float, ...]],
    ) -> None:
        self.limits = limits
        self.points = points
        self._velocities = velocities
        self._accelerations = accelerations
        self._otg = Ruckig(limits.dof)
        self._inp = new_input(limits)
        # Segment 0 goes first once finish() plans it; tail segment k starts at _starts[k] after
        # the end of segment 0.
        self._segments: list[Any] | None = [None]
        self._starts: list[float] = [0.0]
        self._tail_end = 0.0  # where the next tail segment starts, after the end of segment 0
        self._elapsed = points[0].time_from_start  # the tail aims at absolute times from point 0's

    @property
    def velocities(self) -> list[tuple[float, ...]]:
        """The velocity at each point: the client's, else the chosen one (0 at the last)."""
        return list(self._velocities)

    def tail_steps(self) -> Generator[None, None, None]:
        """Plan the tail, one segment per step (the runtime runs them in slices). Raises GoalRejected."""
        while self._plan_next():
            yield

    def _plan_next(self) -> bool:
        """Plan the next tail segment; True while more remain."""
        segments = self._segments
        if segments is None or len(segments) == len(self.points):
            return False
        k = len(segments)
        prev = self.points[k - 1]
        traj = self._segment(
            k, prev.positions, self._velocities[k - 1], self._accelerations[k - 1], self._elapsed
        )
        segments.append(traj)
        self._starts.append(self._tail_end)
        duration = float(traj.duration)
        self._tail_end += duration
        self._elapsed += duration
        return len(segments) < len(self.points)

    def finish(
        self, start_pos: Sequence[float], start_vel: Sequence[float], start_acc: Sequence[float]
    ) -> PlannedTrajectory:
        """Plan what is left and segment 0 from the given start state; the whole plan.

        With the tail planned this costs one segment, however long the trajectory. The planner hands
        its segments to the plan: it can finish once.
        """
        check_start(self.limits, start_pos, start_vel, start_acc)
        while self._plan_next():
            pass
        segments = self._segments
        if segments is None:
            raise RuntimeError("the planner has already finished its plan")
        zeros = [0.0] * self.limits.dof
        first = self._segment(0, start_pos, snap(start_vel, zeros), snap(start_acc, zeros), 0.0)
        d0 = float(first.duration)
        segments[0] = first
        starts = self._starts
        starts[0] = -d0
        self._segments = None
        self._starts = []
        return PlannedTrajectory(segments, starts, d0)

    def _segment(
        self, k: int, pos: Sequence[float], vel: Sequence[float], acc: Sequence[float], elapsed: float
    ) -> Any:
        what = f"point {k}"
        pt = self.points[k]
        inp = self._inp
        requested = pt.time_from_start - elapsed
        inp.current_position = list(pos)
        inp.current_velocity = list(vel)
        inp.current_acceleration = list(acc)
        inp.target_position = list(pt.positions)
        inp.target_velocity = list(self._velocities[k])
        inp.target_acceleration = list(self._accelerations[k])
        inp.minimum_duration = max(requested, 0.0)
        traj = calculate(self._otg, inp, what)
        if traj.duration > requested + TIMING_SLACK:
            inp.minimum_duration = None
            fastest = calculate(self._otg, inp, what).duration
            if fastest > requested:
                raise GoalRejected(
                    f"{what}: reaching it needs at least {_fmt(fastest)} s but time_from_start allows "
                    f"{_fmt(requested)} s"
                )
            raise GoalRejected(
                f"{what}: reaching it in exactly {_fmt(requested)} s is not feasible with its boundary "
                f"velocities (the fastest is {_fmt(fastest)} s, the next feasible above is "
                f"{_fmt(traj.duration)} s)"
            )
        check_extrema(self.limits, traj, pos, what)
        return traj


def plan_trajectory(
    start_pos: Sequence[float],
    start_vel: Sequence[float],
    start_acc: Sequence[float],
    points: Sequence[TrajectoryPoint],
    limits: JointLimits,
) -> PlannedTrajectory:
    """Plan through ``points`` (controller joint order) meeting each time_from_start; GoalRejected if not."""
    check_start(limits, start_pos, start_vel, start_acc)
    return TrajectoryPlanner(points, limits, start_pos).finish(start_pos, start_vel, start_acc)


SNAP_TOLERANCE = 1e-9
"""Differences below this (rad, rad/s, rad/s²) between a segment's end and its target are float noise."""


def snap(values: Sequence[float], targets: Sequence[float]) -> list[float]:
    """``values``, each one within ``SNAP_TOLERANCE`` of its target replaced by the target."""
    return [t if abs(v - t) < SNAP_TOLERANCE else v for v, t in zip(values, targets, strict=True)]
