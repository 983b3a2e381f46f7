"""What Cartesian motion needs of an arm's kinematics: the ``ArmKinematics`` protocol, and which one a
robot of the cell gets (``arm_kinematics``) and where its base frame sits in the world (``base_in_world``).

``UrKinematics`` (ik.py: closed form refined on the calibrated DH) implements it for UR models,
``ChainKinematics`` (chain.py: numeric, on the URDF chain) for custom robots. Poses are URScript's
``(x, y, z, rx, ry, rz)`` of the TCP in the robot's base frame; ``tcp`` is the flange -> TCP pose;
joints are in the controller's joint order (docs/kinematics.md). No numpy: the serve process uses these.
UR arms' named configurations (``Configuration``, ``configuration_of``, ``singularity_name``) live in
configurations.py and are re-exported here.
"""

from __future__ import annotations

from collections.abc import Generator, Sequence
from typing import TYPE_CHECKING, Protocol

from urdaemon.description._transforms import xyz_rpy
from urdaemon.description.calibration import robot_dh
from urdaemon.description.configurations import Configuration, configuration_of, singularity_name
from urdaemon.description.frames import Frame, Pose, compose
from urdaemon.description.ik import UrKinematics
from urdaemon.description.kinematics import KinematicTree
from urdaemon.description.urmodels import load_ur_model

if TYPE_CHECKING:
    from urdaemon.cell.robot_options import Robot

__all__ = [
    "ArmKinematics",
    "Configuration",
    "arm_kinematics",
    "base_in_world",
    "configuration_of",
    "singularity_name",
]

_UR_BASE: Frame = (-1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
"""base_link -> base of a UR arm: turned pi about z (the controller's base frame)."""


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

    def nearest_steps(
        self,
        pose: Sequence[float],
        qnear: Sequence[float],
        tcp: Sequence[float] | None = None,
        max_position_error: float = 1e-10,
        max_orientation_error: float = 1e-10,
    ) -> Generator[None, None, tuple[float, ...] | None]:
        """``nearest`` in bounded chunks: a generator that yields between them (each one Newton
        evaluation, well under the event loop's 0.25 ms slice) and returns what ``nearest`` returns.
        ``ik.run_steps`` runs one to the end."""
        ...

    def jacobian_rows(self, q: Sequence[float], tcp: Sequence[float] | None = None) -> list[list[float]]:
        """6 rows (vx vy vz wx wy wz of the TCP, base frame) x dof columns, plain floats."""
        ...


def arm_kinematics(
    robot: Robot,
    tree: KinematicTree,
    joint_names: Sequence[str],
    bounds: tuple[Sequence[float], Sequence[float]] | None = None,
) -> ArmKinematics:
    """The kinematics Cartesian motion uses for ``robot``, in its base frame and ``joint_names`` order.

    ``bounds`` (lower and upper positions per joint: the cell's joint limits) bound every answer.
    UR models: ``UrKinematics`` on the model and the robot's calibrated DH (``tree`` unused; without
    ``bounds`` its joint limits are the model's). Custom robots: ``ChainKinematics`` on the URDF chain
    ``<prefix><base_link>`` -> ``<prefix><tool_link>`` of ``tree`` (the cell's; without ``bounds``
    the joints are unbounded)."""
    if robot.is_ur:
        return UrKinematics(load_ur_model(robot.model), robot_dh(robot), bounds)
    assert robot.description is not None  # the cell schema guarantees it for model 'custom'
    base = robot.prefix + robot.description.base_link
    tool = robot.prefix + robot.description.tool_link
    from urdaemon.description.chain import ChainKinematics  # custom robots only: the footprint

    return ChainKinematics(tree, base, tool, joint_names, bounds)


def base_in_world(robot: Robot) -> Frame | None:
    """world -> the robot's base frame (UR: ``base``; custom: its base link), or None if not on world.

    The cell file's ``pose`` places base_link in its parent; a UR's ``base`` is base_link turned pi
    about z. A robot mounted on another link (its base moves with it) has no fixed world pose."""
    if robot.pose.parent != "world":
        return None
    mount = xyz_rpy(robot.pose.xyz, robot.pose.rpy)
    return compose(mount, _UR_BASE) if robot.is_ur else mount
