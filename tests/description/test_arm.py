"""Which kinematics a robot gets (arm_kinematics) and where its base frame is in the world (base_in_world).

Reference for the world pose: the cell URDF's own tree (``KinematicTree.link_poses``: the UR's ``base``
link, a custom robot's base_link), built independently from the same cell file. New module: every
test fails on the code before it (no arm.py).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from urdaemon.daemon import describe_cell
from urdaemon.description.arm import ArmKinematics, arm_kinematics, base_in_world
from urdaemon.description.chain import ChainKinematics
from urdaemon.description.frames import Frame, compose, frame_of_pose, inverse
from urdaemon.description.ik import UrKinematics

from .support import DATA, REAL_UR10E, make_cell, write_calibration

SIX = {"xacro": str(DATA / "six_joint_arm.xacro"), "macro": "six_joint_arm"}
MOUNT = {"parent": "world", "xyz": [0.4, -0.3, 0.2], "rpy": [0.3, -0.2, 1.1]}


def _tree_frame(pose: tuple[float, ...]) -> Frame:
    x, y, z, qx, qy, qz, qw = pose
    s = math.sqrt(qx * qx + qy * qy + qz * qz)
    angle = 2.0 * math.atan2(s, qw)
    axis = (0.0, 0.0, 0.0) if s == 0.0 else (qx / s * angle, qy / s * angle, qz / s * angle)
    return frame_of_pose((x, y, z, *axis))


def test_base_in_world_is_the_trees_base_frame(tmp_path: Path) -> None:
    """A rotated and translated UR and custom robot: world -> base is the URDF's base / base_link."""
    cell = make_cell(
        tmp_path,
        {"name": "alice", "model": "ur10e", "pose": MOUNT},
        {"name": "arm", "model": "custom", "description": SIX, "pose": {**MOUNT, "xyz": [-0.5, 0.1, 0.0]}},
    )
    poses = dict(describe_cell(cell).tree.link_poses({}))
    for robot, link in ((cell.robots[0], "alice_base"), (cell.robots[1], "arm_base_link")):
        frame = base_in_world(robot)
        assert frame is not None
        assert np.allclose(frame, _tree_frame(poses[link]), atol=1e-12), robot.name


def test_base_in_world_is_none_on_another_parent(tmp_path: Path) -> None:
    """A robot mounted on another robot's link has no fixed world pose."""
    cell = make_cell(
        tmp_path,
        {"name": "alice", "model": "ur10e"},
        {"name": "bob", "model": "ur3e", "pose": {"parent": "alice_tool0", "xyz": [0, 0, 0.1]}},
    )
    assert base_in_world(cell.robots[0]) is not None
    assert base_in_world(cell.robots[1]) is None


def test_arm_kinematics_per_model(tmp_path: Path) -> None:
    """UR: UrKinematics on the calibrated DH (tool0 where the calibrated URDF puts it); custom: a chain."""
    calibration = write_calibration(tmp_path / "cal.yaml", REAL_UR10E)
    cell = make_cell(
        tmp_path,
        {"name": "alice", "model": "ur10e", "calibration": str(calibration)},
        {"name": "arm", "model": "custom", "description": SIX, "pose": {"xyz": [1.0, 0.0, 0.0]}},
    )
    description = describe_cell(cell)
    kinds: list[ArmKinematics] = []
    for robot in cell.robots:
        limits = description.limits[robot.name]
        kinds.append(arm_kinematics(robot, description.tree, limits.names))
    ur, chain = kinds
    assert isinstance(ur, UrKinematics)
    assert isinstance(chain, ChainKinematics)
    assert (ur.dof, ur.branches, chain.dof, chain.branches) == (6, True, 6, False)
    q = [0.3, -1.2, 1.1, -0.4, 1.0, 0.2]
    names = description.limits["alice"].names
    poses = dict(description.tree.link_poses(dict(zip(names, q, strict=True))))
    base, tool = _tree_frame(poses["alice_base"]), _tree_frame(poses["alice_tool0"])
    assert np.allclose(frame_of_pose(ur.forward(q)), compose(inverse(base), tool), atol=1e-9)
