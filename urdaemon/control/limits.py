"""Validation of client joint data against the controller's joints and limits, and braking bounds.

Every check raises ``GoalRejected`` whose reason names what is wrong (the joint, the value, the limit),
so a client can fix its request without reading the daemon's log.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from urdaemon.errors import GoalRejected
from urdaemon.model import JointLimits

__all__ = [
    "BRAKE_DOWN",
    "BRAKE_UP",
    "apply_permutation",
    "braking_needed",
    "check_accelerations_within",
    "check_finite",
    "check_positions_within",
    "check_scale",
    "check_velocities_within",
    "joint_permutation",
    "reorder",
    "stopping_distance",
]

# Numerical slack for limit comparisons: ruckig's own arithmetic lands a few ulps past a limit.
_EPS = 1e-9


def _fmt(x: float) -> str:
    return f"{x:.6g}"


def check_finite(name: str, values: Sequence[float], joint_names: Sequence[str] | None = None) -> None:
    """Raise GoalRejected naming ``name`` (and the joint, when known) if any value is NaN or infinite."""
    for i, v in enumerate(values):
        if not math.isfinite(v):
            joint = joint_names[i] if joint_names is not None and i < len(joint_names) else f"index {i}"
            raise GoalRejected(f"{name}: {joint} is {v}, not a finite number")


def joint_permutation(given: Sequence[str], controller_names: Sequence[str]) -> tuple[int, ...]:
    """For each controller joint, its index in ``given``; rejects unknown, missing and duplicate names."""
    seen: dict[str, int] = {}
    for i, name in enumerate(given):
        if name in seen:
            raise GoalRejected(f"joint {name!r} is listed twice")
        seen[name] = i
    known = set(controller_names)
    unknown = [name for name in given if name not in known]
    if unknown:
        listed = ", ".join(repr(n) for n in unknown)
        raise GoalRejected(f"unknown joint(s) {listed}; this robot has {', '.join(controller_names)}")
    missing = [name for name in controller_names if name not in seen]
    if missing:
        raise GoalRejected(f"missing joint(s) {', '.join(repr(n) for n in missing)}")
    return tuple(seen[name] for name in controller_names)


def apply_permutation(perm: Sequence[int], values: Sequence[float], what: str) -> tuple[float, ...]:
    """Values in controller order from values in the sender's order; rejects a wrong length."""
    if len(values) != len(perm):
        raise GoalRejected(f"{what} has {len(values)} values for {len(perm)} joints")
    return tuple(float(values[j]) for j in perm)


def reorder(
    joint_names_given: Sequence[str],
    values: Sequence[float],
    controller_names: Sequence[str],
    what: str = "values",
) -> tuple[float, ...]:
    """Map ``values`` given in ``joint_names_given`` order onto ``controller_names`` order."""
    if len(values) != len(joint_names_given):
        raise GoalRejected(f"{what} has {len(values)} values for {len(joint_names_given)} joint names")
    return apply_permutation(joint_permutation(joint_names_given, controller_names), values, what)


def check_positions_within(limits: JointLimits, positions: Sequence[float], what: str) -> None:
    """Raise GoalRejected naming joint, value and limit if a position lies outside [min, max]."""
    for name, p, lo, hi in zip(
        limits.names, positions, limits.min_position, limits.max_position, strict=True
    ):
        if p < lo - _EPS or p > hi + _EPS:
            raise GoalRejected(
                f"{what}: {name} position {_fmt(p)} is outside its limits [{_fmt(lo)}, {_fmt(hi)}]"
            )


def check_velocities_within(limits: JointLimits, velocities: Sequence[float], what: str) -> None:
    """Raise GoalRejected naming joint, value and limit if |velocity| exceeds max_velocity."""
    for name, v, vmax in zip(limits.names, velocities, limits.max_velocity, strict=True):
        if abs(v) > vmax + _EPS:
            raise GoalRejected(f"{what}: {name} velocity {_fmt(v)} exceeds its limit {_fmt(vmax)}")


def check_accelerations_within(limits: JointLimits, accelerations: Sequence[float], what: str) -> None:
    """Raise GoalRejected naming joint, value and limit if |acceleration| exceeds max_acceleration."""
    for name, a, amax in zip(limits.names, accelerations, limits.max_acceleration, strict=True):
        if abs(a) > amax + _EPS:
            raise GoalRejected(f"{what}: {name} acceleration {_fmt(a)} exceeds its limit {_fmt(amax)}")


def check_scale(name: str, value: float) -> None:
    """Raise GoalRejected unless ``value`` lies in (0, 1]."""
    if not (math.isfinite(value) and 0.0 < value <= 1.0):
        raise GoalRejected(f"{name} must be in (0, 1], got {value}")


def stopping_distance(v: float, a: float, amax: float, jmax: float) -> float:
    """Upper bound of the distance a jerk-limited stop covers from speed ``v`` ≥ 0, acceleration ``a``."""
    # ``a`` is signed along the motion; a braking (negative) ``a`` is bounded as if it were 0.
    if a > 0.0:
        # Ramping the acceleration down first: speed still grows by a²/2j, covered at most at peak speed.
        t1 = a / jmax
        vpk = v + a * a / (2.0 * jmax)
        d1 = vpk * t1
    else:
        vpk = v
        d1 = 0.0
    if vpk <= 0.0:
        return d1
    # From zero acceleration a time-optimal stop is point-symmetric in velocity, so it covers vpk·T/2.
    if vpk * jmax >= amax * amax:
        return d1 + 0.5 * vpk * (vpk / amax + amax / jmax)
    return d1 + vpk * math.sqrt(vpk / jmax)


BRAKE_UP = 1
"""Bit set by ``braking_needed`` when motion toward ``max_position`` must stop now."""
BRAKE_DOWN = 2
"""Bit set by ``braking_needed`` when motion toward ``min_position`` must stop now."""


def braking_needed(
    p: float, v: float, a: float, lo: float, hi: float, amax: float, jmax: float, dt: float
) -> int:
    """Bit mask of BRAKE_UP / BRAKE_DOWN: directions in which one more cycle could end a stop past a limit."""
    # The look-ahead assumes the worst cycle (full jerk toward the limit), so braking decided one
    # cycle later than this still ends inside the limit.
    jdt = jmax * dt
    jdt3 = jdt * dt * dt / 6.0
    mask = 0
    ap = a if a > 0.0 else 0.0
    vp = v if v > 0.0 else 0.0
    p1 = p + vp * dt + 0.5 * ap * dt * dt + jdt3
    v1 = vp + ap * dt + 0.5 * jdt * dt
    a1 = min(ap + jdt, amax) if ap < amax else ap
    if p1 + stopping_distance(v1, a1, amax, jmax) >= hi:
        mask = BRAKE_UP
    an = -a if a < 0.0 else 0.0
    vn = -v if v < 0.0 else 0.0
    p1 = p - vn * dt - 0.5 * an * dt * dt - jdt3
    v1 = vn + an * dt + 0.5 * jdt * dt
    a1 = min(an + jdt, amax) if an < amax else an
    if p1 - stopping_distance(v1, a1, amax, jmax) <= lo:
        mask |= BRAKE_DOWN
    return mask
