"""A goal's time scaling: follows the robot's speed scaling without breaking the joint limits.

A goal commands p(τ), its planned trajectory at trajectory time τ, with dτ/dt = s, the time scaling.
By the chain rule the commanded motion is

    v = p'·s,    a = p''·s² + p'·s',    j = p'''·s³ + 3·p''·s·s' + p'·s''.

Goals are planned with |p''| ≤ â = (1 − SLIDER_ACCELERATION_RESERVE)·amax and |p'''| ≤ ĵ =
(1 − SLIDER_JERK_RESERVE)·jmax, and |p'| ≤ vmax, so for ANY goal at any point of it (and without
looking at it) v stays within vmax while s ≤ 1, a within amax while |s'| ≤ (amax − â·s²)/vmax, and j
within jmax while |s''| ≤ (jmax − ĵ·s³ − 3·â·s·|s'|)/vmax: per joint, the smallest counts. The reserves
keep both bounds above zero at s = 1, so the scaling can leave full speed at any moment. ``TimeScaling``
moves s toward the robot's speed scaling along a braking curve inside both bounds, s'' constant over a
cycle and integrated exactly: s never steps, and it arrives at its target (0: the goal pauses) at rest.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from urdaemon.model import JointLimits

__all__ = [
    "SLIDER_ACCELERATION_RESERVE",
    "SLIDER_JERK_RESERVE",
    "TimeScaling",
    "clamp_scaling",
    "planning_limits",
]

SLIDER_ACCELERATION_RESERVE = 0.05
"""Fraction of each joint's max_acceleration goals are not planned with: the room of p'·s'."""
SLIDER_JERK_RESERVE = 0.10
"""Fraction of each joint's max_jerk goals are not planned with: the room of 3·p''·s·s' + p'·s''."""

_SNAP = 1e-9
"""s settles on its target once this close to it, with |s'| below ``_RATE_SNAP``: the jump commands less
than 1e-3 rad/s³ of jerk."""
_RATE_SNAP = 1e-7
_GAIN = 25.0
"""Near its target s converges at this rate (1/s) instead of along the braking curve (no chatter)."""


def clamp_scaling(value: float) -> float:
    """The robot's speed scaling as a target of the time scaling: within [0, 1], NaN as 0."""
    if value >= 1.0:
        return 1.0
    if value > 0.0:
        return value
    return 0.0


def planning_limits(limits: JointLimits) -> JointLimits:
    """``limits`` less the acceleration and jerk reserves of the time scaling: what goals are planned with."""
    return JointLimits(
        names=limits.names,
        min_position=limits.min_position,
        max_position=limits.max_position,
        max_velocity=limits.max_velocity,
        max_acceleration=tuple(a * (1.0 - SLIDER_ACCELERATION_RESERVE) for a in limits.max_acceleration),
        max_jerk=tuple(j * (1.0 - SLIDER_JERK_RESERVE) for j in limits.max_jerk),
        max_effort=limits.max_effort,
    )


def _rate_shares(limits: JointLimits, planned: JointLimits) -> list[float]:
    """Per joint, the share κ ≤ 1 of the acceleration room |s'| may use, so that at any s at least half
    of the jerk room is left for s'' (to brake): 3·â·s·κ·(amax − â·s²)/vmax ≤ (jmax − ĵ·s³)/2."""
    out: list[float] = []
    for v, a, j, a_hat, j_hat in zip(
        limits.max_velocity,
        limits.max_acceleration,
        limits.max_jerk,
        planned.max_acceleration,
        planned.max_jerk,
        strict=True,
    ):
        kappa = 1.0
        for k in range(1, 101):
            s = k / 100.0
            room = 0.5 * (j - j_hat * s**3)
            use = 3.0 * a_hat * s * (a - a_hat * s * s) / v
            if use > room:
                kappa = min(kappa, room / use)
        out.append(kappa)
    return out


class TimeScaling:
    """The time scaling s = dτ/dt of the executing goal and its rate s'."""

    __slots__ = (
        "_a_hat",
        "_amax",
        "_j_hat",
        "_jmax",
        "_kappa",
        "_n",
        "_period",
        "_planned_a",
        "_vmax",
        "rate",
        "value",
    )

    def __init__(self, limits: JointLimits, planned: JointLimits, period: float) -> None:
        self._n = limits.dof
        self._period = period
        self._vmax = list(limits.max_velocity)
        self._amax = list(limits.max_acceleration)
        self._jmax = list(limits.max_jerk)
        self._planned_a = list(planned.max_acceleration)
        self._a_hat = list(planned.max_acceleration)
        self._j_hat = list(planned.max_jerk)
        self._kappa = _rate_shares(limits, planned)
        self.value = 1.0
        """s: trajectory seconds per second."""
        self.rate = 0.0
        """s' (1/s)."""

    def start(self, value: float | None, start_acceleration: Sequence[float]) -> None:
        """A goal starts: at scaling ``value`` and at rest (None: continue, a goal preempting a goal).

        ``start_acceleration`` (trajectory units) bounds |p''| where it exceeds the planned limit (a
        goal taking over a stream starts beyond it, and ruckig brakes that first)."""
        if value is not None:
            self.value = value
            self.rate = 0.0
        planned = self._planned_a
        self._a_hat[:] = [max(planned[i], abs(start_acceleration[i])) for i in range(self._n)]

    def advance(self, target: float) -> float:
        """Move s one cycle toward ``target`` (the robot's speed scaling); the trajectory time it advanced."""
        target = clamp_scaling(target)
        dt = self._period
        s = self.value
        r = self.rate
        error = target - s
        if -_SNAP < error < _SNAP and -_RATE_SNAP < r < _RATE_SNAP:
            self.value = target
            self.rate = 0.0
            return dt * target
        rate_cap, change_cap = self.caps(s, abs(r))
        brake = self._brake(max(s, target), abs(r))
        size = abs(error)
        want = min(rate_cap, math.sqrt(2.0 * brake * size), _GAIN * size)
        if error < 0.0:
            want = -want
        u = (want - r) / dt
        if u > change_cap:
            u = change_cap
        elif u < -change_cap:
            u = -change_cap
        step = dt * (s + dt * (0.5 * r + dt * u / 6.0))
        s += dt * (r + 0.5 * dt * u)
        r += dt * u
        if s >= 1.0:
            s, r = 1.0, min(r, 0.0)
        elif s <= 0.0:
            s, r = 0.0, max(r, 0.0)
        self.value = s
        self.rate = r
        return step if step > 0.0 else 0.0

    def _brake(self, top: float, rate: float) -> float:
        """A |s''| surely available all the way to a target, while s stays below ``top``: half of the
        room at ``top`` at today's |s'| (braking only lowers it), or at any |s'| within its bound
        (κ leaves half of the jerk room there, which shrinks as s grows), whichever is larger."""
        at_rate = 0.5 * self.caps(top, rate)[1]
        top3 = top * top * top
        anyway = math.inf
        for i in range(self._n):
            room = 0.25 * (self._jmax[i] - self._j_hat[i] * top3) / self._vmax[i]
            if room < anyway:
                anyway = room
        return at_rate if at_rate > anyway else anyway

    def caps(self, s: float, rate: float) -> tuple[float, float]:
        """The largest |s'| at scaling ``s``, and the largest |s''| at ``s`` and |s'| = ``rate``."""
        a_hat = self._a_hat
        j_hat = self._j_hat
        kappa = self._kappa
        amax = self._amax
        jmax = self._jmax
        vmax = self._vmax
        s2 = s * s
        s3 = s2 * s
        rate_cap = math.inf
        change_cap = math.inf
        for i in range(self._n):
            v = vmax[i]
            room = kappa[i] * (amax[i] - a_hat[i] * s2) / v
            if room < rate_cap:
                rate_cap = room
            room = (jmax[i] - j_hat[i] * s3 - 3.0 * a_hat[i] * s * rate) / v
            if room < change_cap:
                change_cap = room
        return (rate_cap if rate_cap > 0.0 else 0.0), (change_cap if change_cap > 0.0 else 0.0)
