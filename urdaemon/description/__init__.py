"""The robot-description layer: UR model data, calibration, the cell URDF, fast kinematics and IK.

Importing the package loads no numpy: ``IkSolution`` and ``UrKinematics`` (``ik.py``, numpy) are
imported on first use, so the serve process, which needs forward kinematics only, never loads them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from urdaemon.description.build import build_cell_urdf, robot_joint_names, ur_params
from urdaemon.description.calibration import (
    Calibration,
    Origin,
    UrChain,
    joint_origins,
    load_calibration,
    robot_dh,
)
from urdaemon.description.kinematics import DhKinematics, KinematicTree, TreeJoint
from urdaemon.description.urdf import joint_limits_for, load_urdf
from urdaemon.description.urmodels import (
    DhParameters,
    LinkInertial,
    UrJoint,
    UrModel,
    load_ur_model,
    load_ur_model_file,
)

if TYPE_CHECKING:
    from urdaemon.description.ik import IkSolution, UrKinematics

__all__ = [
    "Calibration",
    "DhKinematics",
    "DhParameters",
    "IkSolution",
    "KinematicTree",
    "LinkInertial",
    "Origin",
    "TreeJoint",
    "UrChain",
    "UrJoint",
    "UrKinematics",
    "UrModel",
    "build_cell_urdf",
    "joint_limits_for",
    "joint_origins",
    "load_calibration",
    "load_ur_model",
    "load_ur_model_file",
    "load_urdf",
    "robot_dh",
    "robot_joint_names",
    "ur_params",
]


def __getattr__(name: str) -> Any:
    """``IkSolution`` and ``UrKinematics``, imported from ``ik.py`` (numpy) when first asked for."""
    if name in ("IkSolution", "UrKinematics"):
        from urdaemon.description import ik

        return getattr(ik, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
