"""A UR arm's named configurations (docs/kinematics.md) and the singularity its joints are nearest,
read from the joints and the arm's proportions (a2, a3, d5) alone: no inverse kinematics."""

from __future__ import annotations

import math
from typing import NamedTuple

from urdaemon.description.ik_types import Vector
from urdaemon.description.urmodels import DhParameters, load_ur_model

__all__ = [
    "Configuration",
    "configuration_of",
    "named_configuration",
    "nearest_singularity",
    "singularity_name",
]


class Configuration(NamedTuple):
    """A UR arm's named configuration (docs/kinematics.md): which of the eight IK branches it is on.

    ``shoulder``: "right" when the wrist centre lies behind joint 2 in the arm's plane (the UR's usual
    working side), "left" when in front. ``elbow``: "up" when sin q3 > 0 with the shoulder right, or
    sin q3 < 0 with it left (the elbow above the shoulder -> wrist line), else "down". ``wrist``: "up"
    when sin q5 > 0, else "down". Each changes only at its singularity (the elbow's also at the
    shoulder's), never along a continuous motion clear of them."""

    shoulder: str
    elbow: str
    wrist: str


def configuration_of(q: Vector, dh: DhParameters | None = None) -> Configuration:
    """The named configuration of joints ``q`` on an arm with DH ``dh`` (default: UR10e proportions).

    The wrist is exact on every UR model; the shoulder side (and with it the elbow's name) needs the
    arm's a2, a3 and d5 only near the shoulder singularity (``UrKinematics.configuration_of`` is exact)."""
    a2, a3, d5 = _arm_proportions(dh)
    return named_configuration(q, a2, a3, d5)


def singularity_name(q: Vector, dh: DhParameters | None = None) -> str:
    """Which singularity ``q`` is nearest: "wrist" (q5 = 0, pi), "elbow" (q3 = 0, pi) or "shoulder"
    (the wrist centre on joint 1's axis plane), by |sin q5|, |sin q3| and the wrist centre's distance
    from the shoulder plane over the arm's reach."""
    a2, a3, d5 = _arm_proportions(dh)
    return nearest_singularity(q, a2, a3, d5)


def _arm_proportions(dh: DhParameters | None) -> tuple[float, float, float]:
    """(a2, a3, d5) of ``dh``, or without one the UR10e's nominal (every UR has a2, a3 < 0 < d5)."""
    real = load_ur_model("ur10e").dh if dh is None else dh
    return real.a[1], real.a[2], real.d[4]


def nearest_singularity(q: Vector, a2: float, a3: float, d5: float) -> str:
    """``singularity_name`` on an arm of proportions a2, a3, d5 (its nominal DH's)."""
    shoulder = abs(_wrist_centre_x(q, a2, a3, d5)) / (abs(a2) + abs(a3) + abs(d5))
    measures = {"wrist": abs(math.sin(q[4])), "elbow": abs(math.sin(q[2])), "shoulder": shoulder}
    return min(measures, key=lambda name: measures[name])


def _wrist_centre_x(q: Vector, a2: float, a3: float, d5: float) -> float:
    """The wrist centre (joint 6's origin) along joint 1's x axis in the arm's plane: its shoulder side."""
    q2, q23 = float(q[1]), float(q[1]) + float(q[2])
    return a2 * math.cos(q2) + a3 * math.cos(q23) + d5 * math.sin(q23 + float(q[3]))


def named_configuration(q: Vector, a2: float, a3: float, d5: float) -> Configuration:
    """``configuration_of`` on an arm of proportions a2, a3, d5 (its nominal DH's)."""
    right = _wrist_centre_x(q, a2, a3, d5) < 0.0
    # With a2, a3 < 0 the elbow is above the shoulder -> wrist line when sin q3 has the sign of
    # -(wrist's x); the wrist centre's side stands for the wrist's (they differ only at the shoulder
    # singularity), so the name cannot change while the arm moves clear of every singularity.
    bend = math.sin(float(q[2]))
    return Configuration(
        "right" if right else "left",
        "up" if (bend > 0.0 if right else bend < 0.0) else "down",
        "up" if math.sin(float(q[4])) > 0.0 else "down",
    )
