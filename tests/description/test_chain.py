"""Numeric kinematics of a URDF chain (urdaemon.description.chain) on custom and UR robots.

References: the cell's ``KinematicTree.link_poses`` (an independent forward walk of the URDF),
central differences for the Jacobian, and ``UrKinematics`` on the UR arms of
configs/dual_robot_mock.yaml. New module: every test fails on the code before it (no chain.py).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from urdaemon.cell import Cell, load_cell
from urdaemon.daemon import describe_cell
from urdaemon.description.arm import arm_kinematics
from urdaemon.description.chain import ChainKinematics
from urdaemon.description.frames import Frame, compose, frame_of_pose, inverse, pose_of_frame
from urdaemon.description.ik import UrKinematics
from urdaemon.errors import DescriptionError

from .support import DATA, make_cell

ROOT = Path(__file__).resolve().parents[2]
SIX = {"xacro": str(DATA / "six_joint_arm.xacro"), "macro": "six_joint_arm"}
TWO = {"xacro": str(DATA / "two_joint_arm.xacro"), "macro": "two_joint_arm"}
TCP = (0.01, -0.02, 0.12, 0.1, -0.2, 0.3)


def _custom(tmp_path: Path, description: dict[str, str]) -> tuple[Cell, ChainKinematics]:
    cell = make_cell(
        tmp_path,
        {
            "name": "arm",
            "model": "custom",
            "description": description,
            "pose": {"parent": "world", "xyz": [0.3, -0.2, 0.1], "rpy": [0.1, 0.2, 0.3]},
        },
    )
    description_ = describe_cell(cell)
    limits = description_.limits["arm"]
    kin = arm_kinematics(
        cell.robots[0], description_.tree, limits.names, (limits.min_position, limits.max_position)
    )
    assert isinstance(kin, ChainKinematics)
    return cell, kin


def _link_pose(cell: Cell, names: tuple[str, ...], q: list[float], link: str) -> tuple[float, ...]:
    """``link`` in ``arm_base_link``'s frame by the tree's own forward walk, as a UR pose."""
    tree = describe_cell(cell).tree
    poses = dict(tree.link_poses(dict(zip(names, q, strict=True))))

    def frame(p: tuple[float, ...]) -> Frame:
        x, y, z, qx, qy, qz, qw = p
        angle = 2.0 * math.atan2(math.sqrt(qx * qx + qy * qy + qz * qz), qw)
        s = math.sqrt(qx * qx + qy * qy + qz * qz)
        axis = (0.0, 0.0, 0.0) if s == 0.0 else (qx / s * angle, qy / s * angle, qz / s * angle)
        return frame_of_pose((x, y, z, *axis))

    return pose_of_frame(compose(inverse(frame(poses["arm_base_link"])), frame(poses[link])))


def _random_q(kin: ChainKinematics, rng: np.random.Generator) -> list[float]:
    lower = np.maximum(np.array(kin._lower), -math.pi)
    upper = np.minimum(np.array(kin._upper), math.pi)
    return list(rng.uniform(lower + 0.05 * (upper - lower), upper - 0.05 * (upper - lower)))


def _close(a: tuple[float, ...], b: tuple[float, ...], tol: float) -> bool:
    fa, fb = frame_of_pose(a), frame_of_pose(b)
    return max(abs(x - y) for x, y in zip(fa, fb, strict=True)) < tol


def test_custom_forward_matches_the_tree(tmp_path: Path) -> None:
    """forward() of the 6-joint custom arm is the tree's tool0 in its base_link, for random joints."""
    cell, kin = _custom(tmp_path, SIX)
    names = describe_cell(cell).limits["arm"].names
    assert kin.dof == 6
    assert kin.branches is False
    rng = np.random.default_rng(3)
    for _ in range(20):
        q = _random_q(kin, rng)
        assert _close(kin.forward(q), _link_pose(cell, names, q, "arm_tool0"), 1e-12)


def test_custom_jacobian_against_central_differences(tmp_path: Path) -> None:
    """jacobian_rows (with a TCP) is the derivative of forward(): linear and angular rows."""
    _, kin = _custom(tmp_path, SIX)
    rng = np.random.default_rng(4)
    for _ in range(10):
        q = _random_q(kin, rng)
        rows = np.array(kin.jacobian_rows(q, TCP))
        base = frame_of_pose(kin.forward(q, TCP))
        h = 1e-6
        for j in range(6):
            plus, minus = list(q), list(q)
            plus[j] += h
            minus[j] -= h
            fp, fm = frame_of_pose(kin.forward(plus, TCP)), frame_of_pose(kin.forward(minus, TCP))
            linear = [(fp[9 + k] - fm[9 + k]) / (2 * h) for k in range(3)]
            turn = pose_of_frame(compose(fp, inverse(fm)))[3:]
            angular = [t / (2 * h) for t in turn]
            assert np.allclose(rows[:3, j], linear, atol=1e-7)
            assert np.allclose(rows[3:, j], angular, atol=1e-7)
        assert base is not None


def test_custom_round_trip(tmp_path: Path) -> None:
    """Poses of random joints come back to those joints from a nearby qnear, to 1e-9 m and rad."""
    _, kin = _custom(tmp_path, SIX)
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(60):
        q = _random_q(kin, rng)
        if np.linalg.svd(np.array(kin.jacobian_rows(q)), compute_uv=False)[-1] < 0.02:
            continue
        pose = kin.forward(q, TCP)
        qnear = [v + rng.uniform(-0.05, 0.05) for v in q]
        found = kin.nearest(pose, qnear, TCP)
        assert found is not None
        assert np.allclose(found, q, atol=1e-9)
        assert _close(kin.forward(found, TCP), pose, 1e-9)
        checked += 1
    assert checked >= 30


def test_custom_far_qnear_restarts_and_stays_within_limits(tmp_path: Path) -> None:
    """From a far qnear a solution is still found (restarts), reaching the pose, inside every limit."""
    _, kin = _custom(tmp_path, SIX)
    rng = np.random.default_rng(6)
    found_count = 0
    for _ in range(20):
        q = _random_q(kin, rng)
        pose = kin.forward(q)
        far = _random_q(kin, rng)
        found = kin.nearest(pose, far)
        if found is None:
            continue
        found_count += 1
        assert _close(kin.forward(found), pose, 1e-9)
        assert all(lo <= v <= hi for v, lo, hi in zip(found, kin._lower, kin._upper, strict=True))
    assert found_count >= 15


def test_custom_out_of_reach_is_none(tmp_path: Path) -> None:
    """A pose 5 m away, and one beyond the slide's stroke, have no solution: None."""
    _, kin = _custom(tmp_path, SIX)
    q = [0.2, 0.3, 0.1, 0.2, -0.3, 0.4]
    x, y, z, rx, ry, rz = kin.forward(q)
    assert kin.nearest((x + 5.0, y, z, rx, ry, rz), q) is None
    assert kin.nearest((x * 3.0, y * 3.0, z, rx, ry, rz), q) is None


def test_fewer_joints_reach_only_their_manifold(tmp_path: Path) -> None:
    """A 2-joint arm (with a mimic joint on the chain) solves poses it can reach, None off them."""
    _, kin = _custom(tmp_path, TWO)
    assert kin.dof == 2
    q = [0.7, 0.15]
    pose = kin.forward(q)
    found = kin.nearest(pose, [0.6, 0.1])
    assert found is not None
    assert np.allclose(found, q, atol=1e-9)
    x, y, z, rx, ry, rz = pose
    assert kin.nearest((x, y, z + 0.01, rx, ry, rz), [0.6, 0.1]) is None
    rows = kin.jacobian_rows(q)
    assert len(rows) == 6
    assert all(len(r) == 2 for r in rows)


def test_ur_chain_agrees_with_ur_kinematics() -> None:
    """On the dual_robot_mock cell URDF, the chain base -> tool0 is UrKinematics: forward, Jacobian, IK."""
    cell = load_cell(ROOT / "configs" / "dual_robot_mock.yaml")
    description = describe_cell(cell)
    rng = np.random.default_rng(7)
    for robot in cell.robots:
        limits = description.limits[robot.name]
        ur = arm_kinematics(robot, description.tree, limits.names)
        assert isinstance(ur, UrKinematics)
        chain = ChainKinematics(
            description.tree,
            robot.prefix + "base",
            robot.prefix + "tool0",
            limits.names,
            (limits.min_position, limits.max_position),
        )
        for _ in range(30):
            q = list(rng.uniform(-3.0, 3.0, 6))
            assert _close(chain.forward(q, TCP), ur.forward(q, TCP), 1e-12)
            assert np.allclose(chain.jacobian_rows(q, TCP), ur.jacobian_rows(q, TCP), atol=1e-12)
            if np.linalg.svd(np.array(ur.jacobian_rows(q)), compute_uv=False)[-1] < 0.02:
                continue
            qnear = [v + rng.uniform(-0.05, 0.05) for v in q]
            pose = ur.forward(q, TCP)
            a, b = chain.nearest(pose, qnear, TCP), ur.nearest(pose, qnear, TCP)
            assert a is not None
            assert b is not None
            assert np.allclose(a, b, atol=1e-9)


def test_bad_chains_are_refused(tmp_path: Path) -> None:
    """Unknown links, and a moving joint that is not one of the given joints, raise DescriptionError."""
    cell, _ = _custom(tmp_path, SIX)
    tree = describe_cell(cell).tree
    names = describe_cell(cell).limits["arm"].names
    with pytest.raises(DescriptionError, match="no link 'arm_nowhere'"):
        ChainKinematics(tree, "arm_base_link", "arm_nowhere", names)
    with pytest.raises(DescriptionError, match="'arm_reach' moves but is not one of"):
        ChainKinematics(tree, "arm_base_link", "arm_tool0", [n for n in names if n != "arm_reach"])
    with pytest.raises(DescriptionError, match="moves 'arm_slider'"):
        ChainKinematics(tree, "arm_slider", "arm_column", names)


def test_joints_off_the_chain_keep_qnear(tmp_path: Path) -> None:
    """A chain ending at the slider leaves the wrist joints out: zero columns, qnear's values kept,
    also when the answer comes from a restart seed."""
    cell, full = _custom(tmp_path, SIX)
    description = describe_cell(cell)
    limits = description.limits["arm"]
    bounds = (limits.min_position, limits.max_position)
    kin = ChainKinematics(description.tree, "arm_base_link", "arm_slider", limits.names, bounds)
    q = [0.4, 0.3, 0.2, 0.0, 0.0, 0.0]
    rows = np.array(kin.jacobian_rows(q))
    assert np.all(rows[:, 3:] == 0.0)
    assert np.any(rows[:, :3] != 0.0)
    pose = kin.forward(q)
    # The second qnear does not converge: the answer comes from a restart seed.
    for qnear in ([0.45, 0.25, 0.25, 1.0, -1.0, 2.0], [-2.9, 1.9, 0.0, 1.0, -1.0, 2.0]):
        found = kin.nearest(pose, qnear)
        assert found is not None
        assert np.allclose(found[:3], q[:3], atol=1e-9)
        assert list(found[3:]) == qnear[3:]
    assert full.dof == kin.dof
