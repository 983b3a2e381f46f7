"""What Cartesian motion needs of an arm's kinematics: the ``ArmKinematics`` protocol.

``UrKinematics`` (ik.py: closed form refined on the calibrated DH) implements it for UR models. Poses
are URScript's ``(x, y, z, rx, ry, rz)`` of the TCP in the robot's base frame; ``tcp`` is the
flange -> TCP pose; joints are in the controller's joint order (docs/kinematics.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from urdaemon.description.frames import Pose

__all__ = ["ArmKinematics"]


class ArmKinematics(Protocol):
    """Forward and inverse kinematics and the Jacobian of one arm, in plain floats."""

    dof: int
    """Joints, in the controller's joint order."""
    branches: bool
    """True when named configurations apply (UR models: ``configuration_of``, ``nearest_in``)."""

    def forward(self, q: Sequence[float], tcp: Sequence[float] | None = None) -> Pose:
        """The TCP pose for joints ``q``."""
        ...

    def nearest(
        self,
        pose: Sequence[float],
        qnear: Sequence[float],
        tcp: Sequence[float] | None = None,
        max_position_error: float = 1e-10,
        max_orientation_error: float = 1e-10,
    ) -> tuple[float, ...] | None:
        """The joints reaching ``pose`` nearest ``qnear`` within the joint limits, or None."""
        ...

    def jacobian_rows(self, q: Sequence[float], tcp: Sequence[float] | None = None) -> list[list[float]]:
        """6 rows (vx vy vz wx wy wz of the TCP, base frame) x dof columns, plain floats."""
        ...
