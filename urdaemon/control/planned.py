"""A plan made before it is handed to the controller, and the check that it starts where the robot rests.

Owns the shape a ready plan has (``ReadyPlan``: what a goal run samples and the ledger frees, the shape
of control/planned_trajectory.py's ``PlannedTrajectory`` and control/sampled.py's ``SampledTrajectory``) and
the check ``MotionController.accept_planned`` makes before starting one: the plan was made for the pose
the robot rests at (a linear goal plans from ``goal_start``, in slices, while the robot waits), so a
new goal must still start there within ``PLAN_START_TOLERANCE`` (a resting arm's noise) and the plan
must start at rest.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from urdaemon.control.stopping import SETTLE_POSITION
from urdaemon.errors import GoalRejected

__all__ = ["PLAN_START_TOLERANCE", "ReadyPlan", "plan_seed"]

PLAN_START_TOLERANCE = SETTLE_POSITION
"""rad: how far the joints a new goal would start from (``goal_start``: the measured pose when idle, the
held setpoint during a stop's hold) may be from a ready plan's start: the stop's settle threshold, the
one level at which this controller counts an arm as resting where it is. The goal starts at the plan's
start, so this is the most the first setpoint can differ from where the robot rests (0.01 rad/s over
one 2 ms cycle); whatever moved the arm since the plan was made (a stream, force mode, a push) is
refused, naming the joint and how far it moved."""
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
    plan: ReadyPlan, resting: Sequence[float], names: Sequence[str]
) -> tuple[list[float], list[float], list[float]]:
    """The plan's start state (positions, zero velocity and acceleration); refused (GoalRejected, naming
    the joint) unless the plan starts at rest within ``PLAN_START_TOLERANCE`` of ``resting`` (where a new
    goal would start now: ``MotionController.goal_start``)."""
    n = len(names)
    start = [0.0] * n
    vel = [0.0] * n
    acc = [0.0] * n
    plan.sample(0.0, start, vel, acc)
    for i, name in enumerate(names):
        if abs(vel[i]) > _REST_VELOCITY:
            raise GoalRejected(f"the plan does not start at rest: {name} starts at {vel[i]:.4g} rad/s")
    worst = max(range(n), key=lambda i: abs(resting[i] - start[i]))
    err = resting[worst] - start[worst]
    if abs(err) > PLAN_START_TOLERANCE:
        raise GoalRejected(
            f"the robot is not at the plan's start: {names[worst]} moved {err:.4g} rad since the plan "
            f"was made (tolerance {PLAN_START_TOLERANCE:.4g} rad, a resting arm's noise); plan again "
            "from where it is"
        )
    return start, [0.0] * n, [0.0] * n
