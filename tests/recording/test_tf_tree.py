"""tf as one transform per URDF joint: each child's pose in its parent, from every link's world pose.
Composing them back down the tree gives the world poses again."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from urdaemon.description.kinematics import compose_poses
from urdaemon.errors import DescriptionError
from urdaemon.recording.tf_tree import inverse_pose, joint_links, joint_transforms

URDF = """<robot name="r">
  <link name="world"/><link name="a_base"/><link name="a_l1"/><link name="a_l2"/><link name="a_tool"/>
  <joint name="a_mount" type="fixed"><parent link="world"/><child link="a_base"/></joint>
  <joint name="a_j1" type="revolute"><parent link="a_base"/><child link="a_l1"/></joint>
  <joint name="a_j2" type="revolute"><parent link="a_l1"/><child link="a_l2"/></joint>
  <joint name="a_tool0" type="fixed"><parent link="a_l1"/><child link="a_tool"/></joint>
</robot>"""

IDENTITY = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def close(a: tuple[float, ...] | list[float], b: tuple[float, ...] | list[float], tol: float = 1e-9) -> bool:
    """Equal poses (a quaternion and its negation are the same rotation)."""
    same = all(math.isclose(x, y, abs_tol=tol) for x, y in zip(a, b, strict=True))
    flipped = all(math.isclose(x, -y, abs_tol=tol) for x, y in zip(a[3:], b[3:], strict=True))
    return same or (
        flipped and all(math.isclose(x, y, abs_tol=tol) for x, y in zip(a[:3], b[:3], strict=True))
    )


def test_joint_links_in_the_files_order() -> None:
    assert joint_links(URDF) == (
        ("world", "a_base"),
        ("a_base", "a_l1"),
        ("a_l1", "a_l2"),
        ("a_l1", "a_tool"),
    )


def test_a_transmissions_joint_is_not_a_joint_of_the_tree() -> None:
    text = (
        '<robot><link name="a"/><link name="b"/>'
        '<joint name="j" type="revolute"><parent link="a"/><child link="b"/></joint>'
        '<transmission name="t"><joint name="j"><hardwareInterface>x</hardwareInterface></joint>'
        "</transmission></robot>"
    )
    assert joint_links(text) == (("a", "b"),)


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("<robot", "not XML"),
        ('<robot><joint name="j"><child link="b"/></joint></robot>', "'j' names no parent"),
        ('<robot><joint name="j"><parent link=""/><child link="b"/></joint></robot>', "'j' names no parent"),
    ],
)
def test_a_bad_urdf_is_named(text: str, says: str) -> None:
    with pytest.raises(DescriptionError, match=says):
        joint_links(text)


@pytest.mark.parametrize(
    "pose",
    [
        IDENTITY,
        (1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0),
        (0.5, -0.2, 0.1, 0.0, 0.0, math.sin(0.6), math.cos(0.6)),
        (0.0, 0.3, 0.0, math.sin(0.4) / math.sqrt(2), math.sin(0.4) / math.sqrt(2), 0.0, math.cos(0.4)),
    ],
)
def test_inverse_pose_undoes_the_pose(pose: tuple[float, ...]) -> None:
    assert close(compose_poses(pose, inverse_pose(pose)), IDENTITY)
    assert close(compose_poses(inverse_pose(pose), pose), IDENTITY)


def test_world_itself_may_be_missing_and_links_without_poses_are_left_out() -> None:
    links = {"a_base": [0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0], "a_l1": [0.5, 0.0, 0.2, 0.0, 0.0, 0.0, 1.0]}
    out = joint_transforms(links, joint_links(URDF))
    assert [(p, c) for p, c, _ in out] == [("world", "a_base"), ("a_base", "a_l1")]
    assert close(out[0][2], (0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    assert close(out[1][2], (0.0, 0.0, 0.2, 0.0, 0.0, 0.0, 1.0))


_unit = st.floats(-1.0, 1.0, allow_nan=False)
_poses = st.tuples(_unit, _unit, _unit, _unit, _unit, _unit, _unit).filter(
    lambda p: math.sqrt(p[3] ** 2 + p[4] ** 2 + p[5] ** 2 + p[6] ** 2) > 0.1
)


def _normalised(p: tuple[float, ...]) -> tuple[float, ...]:
    n = math.sqrt(sum(q * q for q in p[3:]))
    return (*p[:3], *(q / n for q in p[3:]))


@given(st.lists(_poses, min_size=4, max_size=4))
def test_the_joint_transforms_compose_back_to_the_world_poses(poses: list[tuple[float, ...]]) -> None:
    names = ["a_base", "a_l1", "a_l2", "a_tool"]
    links = {name: list(_normalised(p)) for name, p in zip(names, poses, strict=True)}
    world: dict[str, tuple[float, ...]] = {"world": IDENTITY}
    for parent, child, pose in joint_transforms(links, joint_links(URDF)):
        world[child] = compose_poses(world[parent], pose)
    for name in names:
        assert close(world[name], tuple(links[name]), tol=1e-9)
