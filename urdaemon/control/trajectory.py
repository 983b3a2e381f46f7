"""Jerk-limited offline planning with ruckig: multi-point trajectories and point-to-point moves.

Ruckig's community build cannot plan through intermediate waypoints, so a trajectory is a chain of
state-to-state segments, each stretched to the client's timing with ``minimum_duration``. The community
build also ignores position limits, so every segment's position extrema are recomputed and checked here.
"""

from __future__ import annotations

import math
import re
from bisect import bisect_right
from collections.abc import Generator, Sequence
from typing import Any, TypeVar

from ruckig import InputParameter, Result, Ruckig, RuckigError, Synchronization, Trajectory

from urdaemon.control.goals import TrajectoryPoint
from urdaemon.control.limits import (
    check_accelerations_within,
    check_finite,
    check_positions_within,
    check_scale,
    check_velocities_within,
)
from urdaemon.control.stepped import StepCheck
from urdaemon.errors import GoalRejected
from urdaemon.model import JointLimits

__all__ = [
    "MAX_GOAL_TIME_S",
    "TIMING_SLACK",
    "WAYPOINT_VELOCITY_FRACTION",
    "PlannedTrajectory",
    "TrajectoryCheck",
    "TrajectoryPlanner",
    "calculate",
    "check_points",
    "plan_move",
    "plan_trajectory",
    "position_extrema",
    "ruckig_failure_reason",
    "ruckig_result_reason",
]

TIMING_SLACK = 1e-3
"""A segment may take this much longer (s) than the client's timing before the goal is rejected."""

MAX_GOAL_TIME_S = 7200.0
"""Longest goal accepted (s); ruckig's time range ends near 7 600 s."""

WAYPOINT_VELOCITY_FRACTION = 0.9
"""Chosen waypoint velocities stay within this fraction of max_velocity, leaving room to correct."""

_EXTREMA_EPS = 1e-9
_T = TypeVar("_T")


class PlannedTrajectory:
    """A planned jerk-limited trajectory: a chain of ruckig segments sampled by trajectory time.

    Segment ``i`` starts at trajectory time ``starts[i] + shift``: a planner that knows the tail's
    start times before segment 0 (and so the shift) hands its lists over as they are, without a copy
    or a walk over them. The lists are owned by the plan from then on.
    """

    __slots__ = (
        "_count",
        "_index",
        "_shift",
        "_starts",
        "_trajs",
        "duration",
        "final_positions",
        "final_velocities",
    )

    def __init__(self, segments: list[Any], starts: list[float], shift: float = 0.0) -> None:
        if not segments or len(segments) != len(starts):
            raise ValueError("PlannedTrajectory needs one start time per segment, at least one segment")
        self._trajs = segments
        self._starts = starts
        self._shift = shift
        self._count = len(segments)
        self._index = 0
        last = segments[-1]
        self.duration: float = shift + starts[-1] + float(last.duration)
        """Total trajectory time in seconds."""
        end_p, end_v, _ = last.at_time(float(last.duration))
        self.final_positions: tuple[float, ...] = tuple(end_p)
        self.final_velocities: tuple[float, ...] = tuple(end_v)

    @property
    def segment_count(self) -> int:
        """Number of ruckig segments (one per trajectory point)."""
        return self._count

    def sample(self, t: float, pos_out: list[float], vel_out: list[float], acc_out: list[float]) -> None:
        """Write the state at trajectory time ``t`` (clamped to [0, duration]) into the given lists."""
        if t <= 0.0:
            t = 0.0
        elif t >= self.duration:
            t = self.duration
        t -= self._shift
        starts = self._starts
        i = self._index
        if t < starts[i]:
            # Time went backwards (rare): search instead of walking.
            i = bisect_right(starts, t) - 1
            if i < 0:
                i = 0
        last = self._count - 1
        while i < last and t >= starts[i + 1]:
            i += 1
        self._index = i
        p, v, a = self._trajs[i].at_time(t - starts[i])
        pos_out[:] = p
        vel_out[:] = v
        acc_out[:] = a

    def release(self, count: int) -> bool:
        """Drop up to ``count`` segments (the last first), so a long plan is freed a little at a time;
        True while some remain. A plan being released must not be sampled again."""
        trajs = self._trajs
        for _ in range(min(count, len(trajs))):
            trajs.pop()
        if trajs:
            return True
        self._starts.clear()
        self._count = 0
        return False


def _fmt(x: float) -> str:
    return f"{x:.6g}"


def _new_input(limits: JointLimits, velocity_scale: float = 1.0, acceleration_scale: float = 1.0) -> Any:
    inp = InputParameter(limits.dof)
    inp.max_velocity = [v * velocity_scale for v in limits.max_velocity]
    inp.max_acceleration = [a * acceleration_scale for a in limits.max_acceleration]
    inp.max_jerk = list(limits.max_jerk)
    inp.synchronization = Synchronization.Time
    return inp


def _check_start(
    limits: JointLimits, start_pos: Sequence[float], start_vel: Sequence[float], start_acc: Sequence[float]
) -> None:
    n = limits.dof
    for label, values in (
        ("start position", start_pos),
        ("start velocity", start_vel),
        ("start acceleration", start_acc),
    ):
        if len(values) != n:
            raise GoalRejected(f"{label} has {len(values)} values for {n} joints")
        check_finite(label, values, limits.names)


RETRY_LIMIT_SCALES = (1.0 - 1e-9, 1.0 - 1e-6)
"""ruckig 0.19.4 throws on some exactly-degenerate inputs (e.g. a rest-to-rest move of exactly
2·a³/j², where the profile just touches max acceleration: −1.4 → −1.5 rad at a = 5, j = 50).
Retrying with limits tightened by these factors solves them and stays within the limits."""


RUCKIG_ERRORS = (RuckigError, ValueError)
"""What a ruckig call may throw: its own error, or ValueError when the binding meets a result code it
does not know (e.g. −101, a trajectory longer than ruckig's time range, about 7 600 s)."""


def run_robustly(call: Any, inp: Any) -> Any:
    """Run ``call()`` (ruckig calculate or update on ``inp``); if it throws, retry with tighter limits."""
    try:
        return call()
    except RUCKIG_ERRORS as first:
        limits = (list(inp.max_velocity), list(inp.max_acceleration), list(inp.max_jerk))
        try:
            for scale in RETRY_LIMIT_SCALES:
                inp.max_velocity = [v * scale for v in limits[0]]
                inp.max_acceleration = [a * scale for a in limits[1]]
                inp.max_jerk = [j * scale for j in limits[2]]
                try:
                    return call()
                except RUCKIG_ERRORS:
                    continue
        finally:
            inp.max_velocity, inp.max_acceleration, inp.max_jerk = limits
        raise first


RUCKIG_RESULTS: dict[int, str] = {
    0: "still working (0)",
    1: "finished (1)",
    -1: "an unclassified ruckig error (-1)",
    -100: "its input is invalid (-100)",
    -101: "it would last longer than ruckig's numerical time range, about 7 600 s (-101)",
    -102: "it would leave the position limits (-102)",
    -103: "the joints cannot be phase-synchronized (-103)",
    -104: "a limit of zero makes it impossible (-104)",
    -110: "the minimum-time calculation (step 1) failed: the limits or states are numerically extreme (-110)",
    -111: "synchronizing the joints (step 2) failed: the limits or states are numerically extreme (-111)",
}
"""Every result code ruckig (0.19, and the codes later versions added) can return, as a reason."""

_UNKNOWN_CODE = re.compile(r"(-?\d+) is not a valid")
_MAX_DETAIL = 160


def ruckig_result_reason(code: int) -> str:
    """A clear reason for a ruckig result code, including codes this table does not know."""
    return RUCKIG_RESULTS.get(code, f"ruckig returned the unknown result code {code}")


def ruckig_failure_reason(exc: BaseException) -> str:
    """A clear reason for what a ruckig call threw (its error, or the binding's unknown-code ValueError)."""
    text = str(exc).strip()
    unknown = _UNKNOWN_CODE.search(text)
    if unknown is not None:
        return ruckig_result_reason(int(unknown.group(1)))
    # ruckig appends its whole input to the message; the first line is the reason
    first = text.splitlines()[0].strip() if text else ""
    first = first.removeprefix("[ruckig]").strip()
    if "error in step 1" in first:
        return RUCKIG_RESULTS[-110]
    if "error in step 2" in first:
        return RUCKIG_RESULTS[-111]
    if not first:
        return RUCKIG_RESULTS[-1]
    if len(first) > _MAX_DETAIL:
        first = first[:_MAX_DETAIL] + "…"
    return f"its input is invalid: {first} (-100)"


def calculate(otg: Any, inp: Any, what: str) -> Any:
    """Run the offline solver; ruckig's own refusals become GoalRejected naming ``what``."""
    traj = Trajectory(inp.degrees_of_freedom)
    try:
        result = run_robustly(lambda: otg.calculate(inp, traj), inp)
    except RUCKIG_ERRORS as exc:
        raise GoalRejected(f"{what}: ruckig could not plan it: {ruckig_failure_reason(exc)}") from exc
    if result not in (Result.Working, Result.Finished):
        raise GoalRejected(f"{what}: ruckig could not plan it: {ruckig_result_reason(int(result))}")
    return traj


def _phase_extrema(
    lo: float,
    hi: float,
    t: Sequence[float],
    j: Sequence[float],
    a: Sequence[float],
    v: Sequence[float],
    p: Sequence[float],
) -> tuple[float, float]:
    """Widen [lo, hi] by the positions of piecewise-cubic phases, including where velocity crosses 0."""
    for k, dur in enumerate(t):
        # Entries of unused (zero-length) phases may hold stale values, so they are skipped.
        if dur <= 0.0:
            continue
        p0 = p[k]
        v0 = v[k]
        a0 = a[k]
        jk = j[k]
        p_end = p0 + dur * (v0 + dur * (0.5 * a0 + dur * jk / 6.0))
        lo = min(lo, p0, p_end)
        hi = max(hi, p0, p_end)
        roots: tuple[float, ...]
        if jk != 0.0:
            disc = a0 * a0 - 2.0 * jk * v0
            if disc < 0.0:
                continue
            sq = math.sqrt(disc)
            roots = ((-a0 + sq) / jk, (-a0 - sq) / jk)
        elif a0 != 0.0:
            roots = (-v0 / a0,)
        else:
            continue
        for tau in roots:
            if 0.0 < tau < dur:
                x = p0 + tau * (v0 + tau * (0.5 * a0 + tau * jk / 6.0))
                lo = min(lo, x)
                hi = max(hi, x)
    return lo, hi


def position_extrema(traj: Any) -> list[tuple[float, float]]:
    """Per-joint (min, max) position of a ruckig trajectory, computed from its phase profiles."""
    # ruckig 0.19's own ``position_extrema`` misses an extremum inside a constant-acceleration phase
    # (a stop that reverses), so it is recomputed from every phase's jerk, acceleration and velocity.
    out: list[tuple[float, float]] = []
    for prof in traj.profiles[0]:
        pp = prof.p
        lo = min(pp[0], pp[-1])
        hi = max(pp[0], pp[-1])
        brake = prof.brake
        if brake.duration > 0.0:
            lo, hi = _phase_extrema(lo, hi, brake.t, brake.j, brake.a, brake.v, brake.p)
        lo, hi = _phase_extrema(lo, hi, prof.t, prof.j, prof.a, prof.v, pp)
        out.append((lo, hi))
    return out


def _check_extrema(limits: JointLimits, traj: Any, start: Sequence[float], what: str) -> None:
    # A start already outside a limit may only move back in, so the bound relaxes to the start value.
    for i, (ext_min, ext_max) in enumerate(position_extrema(traj)):
        lo = min(limits.min_position[i], start[i]) - _EXTREMA_EPS
        hi = max(limits.max_position[i], start[i]) + _EXTREMA_EPS
        if ext_max > hi:
            raise GoalRejected(
                f"{what}: {limits.names[i]} overshoots to {_fmt(ext_max)}, beyond its limit "
                f"{_fmt(limits.max_position[i])}"
            )
        if ext_min < lo:
            raise GoalRejected(
                f"{what}: {limits.names[i]} overshoots to {_fmt(ext_min)}, beyond its limit "
                f"{_fmt(limits.min_position[i])}"
            )


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


class TrajectoryCheck(StepCheck["TrajectoryPlanner"]):
    """A trajectory's check run in steps (control/stepped.py): ``step(count)`` until it returns False,
    then ``result()``, the planner of the checked points.

    Pure: no clock inside. The caller decides how many steps fit between two turns of its loop, as
    with ``TrajectoryPlanner.plan_next``.
    """

    __slots__ = ()


class TrajectoryPlanner:
    """Plans a multi-point trajectory in steps, so a long one never stalls the caller's loop.

    Segment k ≥ 1 starts exactly at point k−1's target state (position, chosen velocity,
    acceleration), so the whole tail can be planned ahead, one ``plan_next()`` at a time, before
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
        self._inp = _new_input(limits)
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

    @property
    def tail_done(self) -> bool:
        """True when every segment after the first is planned."""
        return self._segments is None or len(self._segments) == len(self.points)

    def plan_next(self) -> bool:
        """Plan the next tail segment; True while more remain. Raises GoalRejected."""
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
        _check_start(self.limits, start_pos, start_vel, start_acc)
        while self.plan_next():
            pass
        segments = self._segments
        if segments is None:
            raise RuntimeError("the planner has already finished its plan")
        zeros = [0.0] * self.limits.dof
        first = self._segment(0, start_pos, _snap(start_vel, zeros), _snap(start_acc, zeros), 0.0)
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
        _check_extrema(self.limits, traj, pos, what)
        return traj


def plan_trajectory(
    start_pos: Sequence[float],
    start_vel: Sequence[float],
    start_acc: Sequence[float],
    points: Sequence[TrajectoryPoint],
    limits: JointLimits,
) -> PlannedTrajectory:
    """Plan through ``points`` (controller joint order) meeting each time_from_start; GoalRejected if not."""
    _check_start(limits, start_pos, start_vel, start_acc)
    return TrajectoryPlanner(points, limits, start_pos).finish(start_pos, start_vel, start_acc)


SNAP_TOLERANCE = 1e-9
"""Differences below this (rad, rad/s, rad/s²) between a segment's end and its target are float noise."""


def _snap(values: Sequence[float], targets: Sequence[float]) -> list[float]:
    return [t if abs(v - t) < SNAP_TOLERANCE else v for v, t in zip(values, targets, strict=True)]


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
    _check_start(limits, start_pos, start_vel, start_acc)
    if len(target) != n:
        raise GoalRejected(f"target has {len(target)} values for {n} joints")
    check_finite("target", target, limits.names)
    check_positions_within(limits, target, "target")
    _check_move_time(limits, start_pos, target, velocity_scale, acceleration_scale)
    otg = Ruckig(n)
    inp = _new_input(limits, velocity_scale, acceleration_scale)
    zeros = [0.0] * n
    inp.current_position = list(start_pos)
    inp.current_velocity = _snap(start_vel, zeros)
    inp.current_acceleration = _snap(start_acc, zeros)
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
    _check_extrema(limits, traj, start_pos, "move")
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
