"""The robot-description layer: UR model data, calibration, the cell URDF, fast kinematics and IK.

Importing the package loads no numpy, nor does anything the serve process uses: forward and inverse
kinematics, Jacobians and damped least squares are plain float math (``ik.py``, ``chain.py``,
``dls.py``); only ``UrKinematics.jacobian`` and ``joint_velocity`` (the fake's) import numpy, inside.
``ChainKinematics`` (``chain.py``, custom robots' numeric IK) is imported when first asked for: a
cell of UR models never loads it (the serve footprint, docs/performance.md).
"""

from __future__ import annotations

from urdaemon.description.arm import (
    ArmKinematics,
    Configuration,
    arm_kinematics,
    base_in_world,
    configuration_of,
    singularity_name,
)
from urdaemon.description.build import build_cell_urdf, robot_joint_names, ur_params
from urdaemon.description.calibration import (
    Calibration,
    Origin,
    UrChain,
    joint_origins,
    load_calibration,
    robot_dh,
)
from urdaemon.description.ik import IkSolution, UrKinematics
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

__all__ = [
    "ArmKinematics",
    "Calibration",
    "ChainKinematics",
    "Configuration",
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
    "arm_kinematics",
    "base_in_world",
    "build_cell_urdf",
    "configuration_of",
    "joint_limits_for",
    "joint_origins",
    "load_calibration",
    "load_ur_model",
    "load_ur_model_file",
    "load_urdf",
    "robot_dh",
    "robot_joint_names",
    "singularity_name",
    "ur_params",
]


def __getattr__(name: str) -> object:
    """``ChainKinematics``, imported from ``chain.py`` when first asked for."""
    if name == "ChainKinematics":
        from urdaemon.description.chain import ChainKinematics

        return ChainKinematics
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
