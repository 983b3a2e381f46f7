"""Our ElementTree reader of the URDF's kinematic facts against yourdfpy, to 1e-12.

Reproduction: before this reader existed the serve process built its tree and limits from
yourdfpy (importing trimesh, scipy, networkx); this proves the replacement reads the same facts
from every cell in configs/ (and the test cells) so serving is unchanged.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.description.support import make_cell
from urdaemon.cell import Cell, load_cell
from urdaemon.description import KinematicTree, build_cell_urdf, joint_limits_for, load_urdf
from urdaemon.description.urdf_facts import read_urdf_facts
from urdaemon.errors import DescriptionError

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = sorted((ROOT / "configs").glob("*.yaml"))
DATA = Path(__file__).resolve().parent / "data"
TOL = 1e-12


def _close(a: Any, b: Any) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return abs(float(a) - float(b)) <= TOL


def _assert_same_joint(ours: Any, theirs: Any) -> None:
    assert (ours.name, ours.type, ours.parent, ours.child) == (
        theirs.name,
        theirs.type,
        theirs.parent,
        theirs.child,
    )
    assert (ours.origin is None) == (theirs.origin is None)
    if ours.origin is not None:
        for i in range(4):
            for j in range(4):
                assert _close(ours.origin[i][j], theirs.origin[i][j]), (ours.name, i, j)
    assert (ours.axis is None) == (theirs.axis is None)
    if ours.axis is not None:
        assert all(_close(a, b) for a, b in zip(ours.axis, theirs.axis, strict=True))
    assert (ours.limit is None) == (theirs.limit is None)
    if ours.limit is not None:
        for name in ("lower", "upper", "velocity", "effort"):
            assert _close(getattr(ours.limit, name), getattr(theirs.limit, name)), (ours.name, name)
    assert (ours.mimic is None) == (theirs.mimic is None)
    if ours.mimic is not None:
        assert ours.mimic.joint == theirs.mimic.joint
        assert _close(ours.mimic.multiplier, theirs.mimic.multiplier)
        assert _close(ours.mimic.offset, theirs.mimic.offset)


def _assert_cell_matches(cell: Cell) -> None:
    text = build_cell_urdf(cell)
    ours, theirs = read_urdf_facts(text), load_urdf(text)
    assert ours.base_link == theirs.base_link
    assert [j.name for j in ours.robot.joints] == [j.name for j in theirs.robot.joints]
    assert list(ours.robot.links) == [link.name for link in theirs.robot.links]
    for joint in theirs.robot.joints:
        _assert_same_joint(ours.joint_map[joint.name], joint)
    for robot in cell.robots:
        assert joint_limits_for(robot, ours) == joint_limits_for(robot, theirs)
    tree_ours, tree_theirs = KinematicTree.from_urdf(ours), KinematicTree.from_urdf(theirs)
    assert tree_ours.links == tree_theirs.links
    positions = {j.name: 0.1 * (i + 1) for i, j in enumerate(theirs.robot.joints)}
    for (la, pa), (lb, pb) in zip(
        tree_ours.link_poses(positions), tree_theirs.link_poses(positions), strict=True
    ):
        assert la == lb
        assert all(abs(a - b) <= TOL for a, b in zip(pa, pb, strict=True))


@pytest.mark.parametrize("config", CONFIGS, ids=[c.name for c in CONFIGS])
def test_facts_match_yourdfpy_on_every_config(config: Path) -> None:
    _assert_cell_matches(load_cell(config))


def test_facts_match_yourdfpy_on_a_custom_arm_beside_a_ur(tmp_path: Path) -> None:
    arm = {"xacro": str(DATA / "two_joint_arm.xacro"), "macro": "two_joint_arm"}
    cell = make_cell(
        tmp_path,
        {"name": "alice", "model": "ur5e", "pose": {"xyz": [0.3, -0.2, 0.1], "rpy": [0.1, 0.2, 0.3]}},
        {"name": "arm", "model": "custom", "description": arm, "pose": {"xyz": [1, 0, 0]}},
    )
    _assert_cell_matches(cell)


def test_unreadable_urdf_is_a_description_error() -> None:
    with pytest.raises(DescriptionError, match="cannot read the URDF"):
        read_urdf_facts("<robot name='x'><joint name='j'>")
