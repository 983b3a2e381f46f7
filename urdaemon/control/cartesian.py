"""Cartesian motion limits of a robot's TCP: the one value type linear goals and twists share.

A linear goal (control/linear.py) time-parameterises its straight lines with these limits; a twist
stream (control/twist.py) smooths and caps its commands with them. The TCP point's linear limits and the
TCP frame's angular limits are separate, as in URScript's ``movel`` (``v``, ``a``) and ``speedl``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["CartesianLimits"]


@dataclass(frozen=True, slots=True)
class CartesianLimits:
    """Limits of the TCP's motion: its point's linear and its frame's angular speed, acceleration, jerk.

    Units: m/s, m/s^2, m/s^3 for the TCP point; rad/s, rad/s^2, rad/s^3 for the TCP frame's rotation.
    Every value must be finite and > 0.
    """

    speed: float
    acceleration: float
    jerk: float
    angular_speed: float
    angular_acceleration: float
    angular_jerk: float

    def __post_init__(self) -> None:
        for name in (
            "speed",
            "acceleration",
            "jerk",
            "angular_speed",
            "angular_acceleration",
            "angular_jerk",
        ):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"CartesianLimits.{name} must be a finite number > 0, got {value!r}")

    def scaled(self, k: float) -> CartesianLimits:
        """These limits for a motion slowed by ``k`` >= 1 in time: speed/k, acceleration/k^2, jerk/k^3."""
        k2 = k * k
        k3 = k2 * k
        return CartesianLimits(
            self.speed / k,
            self.acceleration / k2,
            self.jerk / k3,
            self.angular_speed / k,
            self.angular_acceleration / k2,
            self.angular_jerk / k3,
        )
