"""A client's goal request put into the controller's terms, or refused with the reason, before it runs.

Owns the controller's default tolerances and the cache of the joint orders clients send. Maps a
request's values into the controller's joint order (and plans a move to them), checks a trajectory's
points step by step (the acceleration reserve the time scaling keeps, then the planner's own checks)
and completes the request's tolerances with the defaults. Changes nothing in the controller: the start
state a trajectory is checked from comes in as a function, read when the check gets there.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass, replace

from urdaemon.control.goal_types import Tolerances, TrajectoryPoint
from urdaemon.control.limits import apply_permutation, joint_permutation
from urdaemon.control.move import plan_move
from urdaemon.control.planned_trajectory import PlannedTrajectory
from urdaemon.control.scaling import SLIDER_ACCELERATION_RESERVE
from urdaemon.control.trajectory import MAX_GOAL_TIME_S, TrajectoryPlanner, check_points
from urdaemon.errors import GoalRejected
from urdaemon.model import JointLimits

__all__ = ["MAX_JOINT_TOLERANCE", "GoalIntake", "GoalTolerances"]

MAX_JOINT_TOLERANCE = 2.0 * math.pi
"""Largest finite path or goal tolerance of a joint (rad): one turn; infinity switches the check off."""
_PERM_CACHE_SIZE = 32


@dataclass(frozen=True, slots=True)
class GoalTolerances:
    """A goal's tolerances, complete: per joint in controller order (rad), and the goal time (s)."""

    path: tuple[float, ...]
    goal: tuple[float, ...]
    goal_time: float

    def without_path(self) -> GoalTolerances:
        """These with the path check off (a goal the robot interpolates itself)."""
        return replace(self, path=(math.inf,) * len(self.path))


class GoalIntake:
    """Checks goal requests against one robot's joints and limits; maps them into its joint order."""

    __slots__ = ("_defaults", "_perm_cache", "limits", "names", "plan_limits")

    def __init__(self, limits: JointLimits, plan_limits: JointLimits, defaults: GoalTolerances) -> None:
        self.limits = limits
        self.plan_limits = plan_limits
        self.names = limits.names
        self._defaults = defaults
        self._perm_cache: dict[tuple[str, ...], tuple[int, ...]] = {}

    def permutation(self, joint_names: Sequence[str]) -> tuple[int, ...]:
        """For each controller joint, its index in ``joint_names``; rejects unknown, missing, twice listed."""
        key = tuple(joint_names)
        perm = self._perm_cache.get(key)
        if perm is None:
            perm = joint_permutation(key, self.names)
            if len(self._perm_cache) >= _PERM_CACHE_SIZE:
                self._perm_cache.clear()
            self._perm_cache[key] = perm
        return perm

    def check_steps(
        self,
        joint_names: Sequence[str],
        points: Sequence[TrajectoryPoint],
        seed: Callable[[], Sequence[float]],
    ) -> Generator[None, None, TrajectoryPlanner]:
        """Check a trajectory a point a step; its result is the planner of the points from ``seed()``."""
        perm = self.permutation(joint_names)
        if not points:
            raise GoalRejected("the trajectory has no points")
        mapped: list[TrajectoryPoint] = []
        for k, pt in enumerate(points):
            mapped.append(_mapped_point(perm, k, pt))
            yield
        del points  # the caller may free the sender's points from here on
        for k, pt in enumerate(mapped):
            self._check_reserve(k, pt)
            yield
        return (yield from check_points(mapped, self.plan_limits, seed()))

    def plan_move(
        self,
        joint_names: Sequence[str],
        positions: Sequence[float],
        seed: tuple[list[float], list[float], list[float]],
        duration: float | None,
        velocity_scale: float,
        acceleration_scale: float,
    ) -> PlannedTrajectory:
        """A point-to-point move to ``positions`` (in ``joint_names`` order) from ``seed``."""
        target = apply_permutation(self.permutation(joint_names), positions, "positions")
        return plan_move(
            *seed,
            target,
            self.plan_limits,
            duration=duration,
            velocity_scale=velocity_scale,
            acceleration_scale=acceleration_scale,
        )

    def check_planner(self, planner: TrajectoryPlanner) -> None:
        """Refuse a planner another controller prepared (it planned with other limits)."""
        if planner.limits is not self.plan_limits:
            raise ValueError("the planner was prepared by another controller")

    def _check_reserve(self, k: int, pt: TrajectoryPoint) -> None:
        """Refuse client accelerations within a limit but inside the reserve kept for the speed scaling."""
        if pt.accelerations is None:
            return
        planned = self.plan_limits.max_acceleration
        amax = self.limits.max_acceleration
        for i, a in enumerate(pt.accelerations):
            if planned[i] < abs(a) <= amax[i] * (1.0 + 1e-9):
                share = 100.0 * (1.0 - SLIDER_ACCELERATION_RESERVE)
                raise GoalRejected(
                    f"point {k}: {self.names[i]} acceleration {a:.6g} exceeds {planned[i]:.6g}, "
                    f"{share:.0f} % of its limit {amax[i]:.6g}: the rest is kept so the speed "
                    "scaling can change smoothly while a goal runs"
                )

    def tolerances(self, given: Tolerances | None) -> GoalTolerances:
        """A request's tolerances checked and completed with the defaults; refusals name the value."""
        if given is None:
            return self._defaults
        path = self._joint_tolerances("path", given.path, self._defaults.path)
        goal = self._joint_tolerances("goal", given.goal, self._defaults.goal)
        goal_time = self._defaults.goal_time
        if given.goal_time is not None:
            if not (given.goal_time >= 0.0):
                raise GoalRejected(f"goal_time tolerance must be >= 0, got {given.goal_time}")
            if MAX_GOAL_TIME_S < given.goal_time < math.inf:
                raise GoalRejected(
                    f"goal_time tolerance is {given.goal_time:.6g} s, more than the longest goal "
                    f"({MAX_GOAL_TIME_S:.6g} s)"
                )
            goal_time = float(given.goal_time)
        return GoalTolerances(path, goal, goal_time)

    def _joint_tolerances(
        self, label: str, values: tuple[float, ...] | None, default: tuple[float, ...]
    ) -> tuple[float, ...]:
        if values is None:
            return default
        n = len(self.names)
        if len(values) != n:
            raise GoalRejected(f"{label} tolerances have {len(values)} values for {n} joints")
        for name, value in zip(self.names, values, strict=True):
            # Infinity is allowed: it switches the check off for that joint.
            if not (value > 0.0):
                raise GoalRejected(f"{label} tolerance of {name} must be > 0, got {value}")
            if MAX_JOINT_TOLERANCE < value < math.inf:
                raise GoalRejected(
                    f"{label} tolerance of {name} is {value:.6g}, more than one turn "
                    f"({MAX_JOINT_TOLERANCE:.6g} rad); leave it out for the default"
                )
        return tuple(float(v) for v in values)


def _mapped_point(perm: Sequence[int], k: int, pt: TrajectoryPoint) -> TrajectoryPoint:
    """Point ``k`` in controller joint order; rejects a wrong length."""
    return TrajectoryPoint(
        positions=apply_permutation(perm, pt.positions, f"point {k} positions"),
        time_from_start=float(pt.time_from_start),
        velocities=(
            None if pt.velocities is None else apply_permutation(perm, pt.velocities, f"point {k} velocities")
        ),
        accelerations=(
            None
            if pt.accelerations is None
            else apply_permutation(perm, pt.accelerations, f"point {k} accelerations")
        ),
    )
