"""A plan made before it is handed to the controller, and the check that it starts where the robot rests.

Owns the shape a ready plan has (``ReadyPlan``: what a goal run samples and the ledger frees, the shape
of control/trajectory.py's ``PlannedTrajectory`` and control/sampled.py's ``SampledTrajectory``) and
the check ``MotionController.accept_planned`` makes before starting one: the plan was made for the pose
the robot rests at (a linear goal plans from ``goal_start``, in slices, while the robot waits), so the
robot must still be there within ``PLAN_START_TOLERANCE`` and the plan must start at rest.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from urdaemon.errors import GoalRejected

__all__ = ["PLAN_START_TOLERANCE", "ReadyPlan", "plan_seed"]

PLAN_START_TOLERANCE = 1e-3
"""rad: how far a measured joint may be from a ready plan's start. The goal starts at the plan's start,
so this is the most the first setpoint can differ from the measured pose; a resting arm's measurement
noise is orders of magnitude smaller, an arm that moved since the plan was made is refused."""
_REST_VELOCITY = 1e-9
"""rad/s: the largest start velocity that counts as a plan starting at rest (float rounding)."""


class ReadyPlan(Protocol):
    """A planned goal, ready to run: sampled on trajectory time, freed a few segments at a time."""

    @property
    def duration(self) -> float: ...
    @property
    def final_positions(self) -> tuple[float, ...]: ...
    @property
    def final_velocities(self) -> tuple[float, ...]: ...
    @property
    def segment_count(self) -> int: ...
    def sample(self, t: float, pos_out: list[float], vel_out: list[float], acc_out: list[float]) -> None: ...
    def release(self, count: int) -> bool: ...


def plan_seed(
    plan: ReadyPlan, measured: Sequence[float], names: Sequence[str]
) -> tuple[list[float], list[float], list[float]]:
    """The plan's start state (positions, zero velocity and acceleration); refused (GoalRejected, naming
    the joint) unless the plan starts at rest within ``PLAN_START_TOLERANCE`` of ``measured``."""
    n = len(names)
    start = [0.0] * n
    vel = [0.0] * n
    acc = [0.0] * n
    plan.sample(0.0, start, vel, acc)
    for i, name in enumerate(names):
        if abs(vel[i]) > _REST_VELOCITY:
            raise GoalRejected(f"the plan does not start at rest: {name} starts at {vel[i]:.4g} rad/s")
    worst = max(range(n), key=lambda i: abs(measured[i] - start[i]))
    err = measured[worst] - start[worst]
    if abs(err) > PLAN_START_TOLERANCE:
        raise GoalRejected(
            f"the robot is not at the plan's start: {names[worst]} is {err:.4g} rad from it "
            f"(tolerance {PLAN_START_TOLERANCE:.4g} rad); plan again from where it is"
        )
    return start, [0.0] * n, [0.0] * n
