"""The plain-float kinematics against the independent DH FK and against yourdfpy."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from urdaemon.cell import ur_models
from urdaemon.description import DhKinematics, KinematicTree, build_cell_urdf, load_ur_model, load_urdf
from urdaemon.description.frames import frame_of_pose
from urdaemon.description.kinematics import ToolOffset, quaternion_of

from .support import DATA, REAL_UR10E, dh_fk, make_cell, quat_matrix, random_calibration

TWO_JOINT = {"xacro": str(DATA / "two_joint_arm.xacro"), "macro": "two_joint_arm"}


def _assert_pose(pose: tuple[float, ...], expected: np.ndarray) -> None:
    assert len(pose) == 7
    x, y, z, qx, qy, qz, qw = pose
    assert qw >= 0.0
    assert math.isclose(qx * qx + qy * qy + qz * qz + qw * qw, 1.0, abs_tol=1e-12)
    np.testing.assert_allclose((x, y, z), expected[:3, 3], rtol=0, atol=1e-9)
    np.testing.assert_allclose(quat_matrix(qx, qy, qz, qw), expected[:3, :3], rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", ur_models())
def test_tool_pose_equals_the_dh_fk(name: str) -> None:
    rng = np.random.default_rng(ur_models().index(name))
    nominal = load_ur_model(name).dh
    for dh in (nominal, random_calibration(nominal, rng)):
        kinematics = DhKinematics(dh)
        for _ in range(100):
            q = rng.uniform(-2 * math.pi, 2 * math.pi, 6)
            _assert_pose(kinematics.tool_pose(q.tolist()), dh_fk(dh, q))


def test_tool_pose_of_a_real_calibration() -> None:
    rng = np.random.default_rng(99)
    kinematics = DhKinematics(REAL_UR10E)
    for _ in range(100):
        q = rng.uniform(-math.pi, math.pi, 6)
        _assert_pose(kinematics.tool_pose(tuple(q.tolist())), dh_fk(REAL_UR10E, q))


def test_tool_pose_at_zero_is_the_known_ur10e_pose() -> None:
    # At q = 0 a UR10e's tool sits at (a2 + a3, -(d4 + d6), d1 - d5), z pointing along -y of base.
    x, y, z, *quaternion = DhKinematics(load_ur_model("ur10e").dh).tool_pose([0.0] * 6)
    assert (x, y, z) == pytest.approx((-0.6127 - 0.57155, -(0.17415 + 0.11655), 0.1807 - 0.11985), abs=1e-12)
    np.testing.assert_allclose(quat_matrix(*quaternion)[:, 2], (0.0, -1.0, 0.0), atol=1e-12)


def test_tool_pose_needs_six_positions() -> None:
    with pytest.raises(ValueError, match="zip"):
        DhKinematics(load_ur_model("ur5e").dh).tool_pose([0.0] * 5)


@pytest.mark.parametrize(
    "matrix",
    [
        np.diag([1.0, 1.0, 1.0]),
        np.diag([1.0, -1.0, -1.0]),  # half turns: the three non-trace branches
        np.diag([-1.0, 1.0, -1.0]),
        np.diag([-1.0, -1.0, 1.0]),
    ],
)
def test_quaternion_of_half_turns(matrix: np.ndarray) -> None:
    q = quaternion_of(*matrix.flatten().tolist())
    np.testing.assert_allclose(quat_matrix(*q), matrix, atol=1e-15)


def test_quaternion_of_random_rotations() -> None:
    rng = np.random.default_rng(21)
    for _ in range(1000):
        raw = rng.normal(size=4)
        x, y, z, w = raw / np.linalg.norm(raw)
        matrix = quat_matrix(x, y, z, w)
        q = quaternion_of(*matrix.flatten().tolist())
        assert q[3] >= 0.0
        np.testing.assert_allclose(np.abs(q), np.abs((x, y, z, w)), atol=1e-12)
        np.testing.assert_allclose(quat_matrix(*q), matrix, atol=1e-14)


def _two_robot_cell(tmp_path: Path, *extra: dict[str, Any]) -> Any:
    return make_cell(
        tmp_path,
        {"name": "alice", "model": "ur10e", "pose": {"xyz": [0.5, 0.0, 0.0]}},
        {"name": "bob", "model": "ur3e", "pose": {"xyz": [-0.5, 0.0, 0.0], "rpy": [0.0, 0.0, math.pi]}},
        *extra,
    )


def _assert_tree_matches_yourdfpy(urdf: Any, rng: np.random.Generator, count: int) -> None:
    tree = KinematicTree.from_urdf(urdf)
    assert tree.root == "world"
    assert set(tree.links) == {link.name for link in urdf.robot.links}
    names = list(urdf.actuated_joint_names)
    for _ in range(count):
        values = rng.uniform(-math.pi, math.pi, len(names)).tolist()
        positions = dict(zip(names, values, strict=True))
        urdf.update_cfg(positions)
        poses = tree.link_poses(positions)
        assert [name for name, _ in poses] == list(tree.links)
        for name, pose in poses:
            _assert_pose(pose, urdf.get_transform(name, "world"))


def test_link_poses_match_yourdfpy_for_two_arms(tmp_path: Path) -> None:
    urdf = load_urdf(build_cell_urdf(_two_robot_cell(tmp_path)))
    _assert_tree_matches_yourdfpy(urdf, np.random.default_rng(8), 50)


def test_link_poses_handle_prismatic_slanted_and_mimic_joints(tmp_path: Path) -> None:
    arm = {
        "name": "arm",
        "model": "custom",
        "description": TWO_JOINT,
        "pose": {"parent": "bob_tool0", "rpy": [0.3, 0, 0]},
    }
    urdf = load_urdf(build_cell_urdf(_two_robot_cell(tmp_path, arm)))
    tree = KinematicTree.from_urdf(urdf)
    finger = next(j for j in tree.joints if j.name == "arm_finger_joint")
    assert finger.mimic == ("arm_yaw", -0.5, 0.1)
    reach = next(j for j in tree.joints if j.name == "arm_reach")
    assert reach.axis == pytest.approx((0.6, 0.8, 0.0), abs=1e-15)
    _assert_tree_matches_yourdfpy(urdf, np.random.default_rng(9), 30)


def test_joints_left_out_are_at_zero(tmp_path: Path) -> None:
    urdf = load_urdf(build_cell_urdf(_two_robot_cell(tmp_path)))
    tree = KinematicTree.from_urdf(urdf)
    urdf.update_cfg(dict.fromkeys(urdf.actuated_joint_names, 0.0))
    poses = dict(tree.link_poses({}))
    assert poses["world"] == (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    for name in ("alice_tool0", "bob_tool0", "bob_base"):
        _assert_pose(poses[name], urdf.get_transform(name, "world"))


def test_bob_tool0_in_world_agrees_with_dh(tmp_path: Path) -> None:
    urdf = load_urdf(build_cell_urdf(_two_robot_cell(tmp_path)))
    tree = KinematicTree.from_urdf(urdf)
    kinematics = DhKinematics(load_ur_model("ur3e").dh)
    # bob's controller base: at x = -0.5 turned by π (pose), then π again (base_link → base)
    base_in_world = np.eye(4)
    base_in_world[0, 3] = -0.5
    rng = np.random.default_rng(4)
    for _ in range(20):
        q = rng.uniform(-math.pi, math.pi, 6).tolist()
        poses = dict(
            tree.link_poses(
                {
                    f"bob_{j}": v
                    for j, v in zip(
                        (
                            "shoulder_pan_joint",
                            "shoulder_lift_joint",
                            "elbow_joint",
                            "wrist_1_joint",
                            "wrist_2_joint",
                            "wrist_3_joint",
                        ),
                        q,
                        strict=True,
                    )
                }
            )
        )
        x, y, z, *quaternion = kinematics.tool_pose(q)
        expected = np.eye(4)
        expected[:3, :3] = quat_matrix(*quaternion)
        expected[:3, 3] = (x, y, z)
        _assert_pose(poses["bob_tool0"], base_in_world @ expected)


CHAIN_URDF = """<robot name="chain">
  <link name="root"/><link name="a"/><link name="b"/><link name="c"/>
  <joint name="j1" type="revolute">
    <parent link="root"/><child link="a"/><axis xyz="0 0 2"/>
    <limit lower="-3" upper="3" velocity="1" effort="1"/>
  </joint>
  <joint name="j3" type="continuous">
    <parent link="b"/><child link="c"/><axis xyz="1 0 0"/>
    <mimic joint="j2" multiplier="-1" offset="0.25"/>
  </joint>
  <joint name="j2" type="prismatic">
    <parent link="a"/><child link="b"/><origin xyz="1 0 0"/><axis xyz="2 0 0"/>
    <limit lower="-9" upper="9" velocity="1" effort="1"/>
    <mimic joint="j1" multiplier="2" offset="0.5"/>
  </joint>
</robot>"""


def test_axes_are_normalised_and_mimic_chains_followed() -> None:
    tree = KinematicTree.from_urdf(load_urdf(CHAIN_URDF))
    assert tree.links == ("root", "a", "b", "c")  # parents first, whatever the file order
    assert next(j for j in tree.joints if j.name == "j3").mimic == ("j1", -2.0, -0.25)
    for q in (-1.0, 0.0, 0.4, 2.5):
        poses = dict(tree.link_poses({"j1": q}))
        slide = 1.0 + 2.0 * q + 0.5  # origin x plus j2 = 2·j1 + 0.5 along the unit x axis
        turn = -(2.0 * q + 0.5) + 0.25  # j3 = -j2 + 0.25
        rz = np.array([[math.cos(q), -math.sin(q), 0], [math.sin(q), math.cos(q), 0], [0, 0, 1]])
        rx = np.array([[1, 0, 0], [0, math.cos(turn), -math.sin(turn)], [0, math.sin(turn), math.cos(turn)]])
        expected = np.eye(4)
        expected[:3, :3] = rz @ rx
        expected[:3, 3] = rz @ np.array([slide, 0.0, 0.0])
        _assert_pose(poses["c"], expected)


def test_tool_offset_composes_the_tcp_with_the_flange_pose() -> None:
    """The TCP pose is the tool0 frame times the TCP frame, checked with matrices on random joints."""
    kinematics = DhKinematics(REAL_UR10E)
    rng = np.random.default_rng(17)
    for _ in range(50):
        tcp = [*rng.uniform(-0.3, 0.3, 3), *rng.uniform(-1.5, 1.5, 3)]
        q = rng.uniform(-math.pi, math.pi, 6)
        flange = kinematics.tool_pose(list(q))
        out = ToolOffset(tcp).apply(flange)
        f = np.array(frame_of_pose(tcp))
        r_tcp, t_tcp = f[:9].reshape(3, 3), f[9:]
        r_flange = quat_matrix(*flange[3:])
        assert np.allclose(out[:3], np.array(flange[:3]) + r_flange @ t_tcp, atol=1e-12)
        assert np.allclose(quat_matrix(*out[3:]), r_flange @ r_tcp, atol=1e-12)
