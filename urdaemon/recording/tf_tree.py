"""The cell's tf as Foxglove's 3-D panel wants it next to the URDF: one transform per URDF joint,
parent link → child link, computed from the world pose of every link that the daemon's tf gives.

The panel's URDF layer puts each joint's own transform (its origin, the joint at zero) into the
panel's transform tree; a frame there has one parent. Transforms from ``world`` to every link would
give each link a second parent and the two would take turns (docs/foxglove.md). Pure: no Zenoh, no
Foxglove.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence

from urdaemon.description.kinematics import compose_poses
from urdaemon.errors import DescriptionError

__all__ = ["Transform", "inverse_pose", "joint_links", "joint_transforms", "world_poses"]

Transform = tuple[str, str, tuple[float, ...]]
"""(parent link, child link, the child's pose in the parent: x, y, z, qx, qy, qz, qw)."""


def joint_links(urdf: str) -> tuple[tuple[str, str], ...]:
    """(parent link, child link) of every joint of the URDF text, in the file's order."""
    try:
        root = ET.fromstring(urdf)
    except ET.ParseError as err:
        raise DescriptionError(f"the cell URDF is not XML: {err}") from err
    pairs = []
    for joint in root.findall("joint"):  # the robot's own joints, not a transmission's
        parent, child = joint.find("parent"), joint.find("child")
        if parent is None or child is None or not parent.get("link") or not child.get("link"):
            raise DescriptionError(f"URDF joint {joint.get('name')!r} names no parent or child link")
        pairs.append((str(parent.get("link")), str(child.get("link"))))
    return tuple(pairs)


def inverse_pose(pose: Sequence[float]) -> tuple[float, ...]:
    """The pose that undoes ``pose`` (x, y, z, qx, qy, qz, qw), for a unit quaternion."""
    x, y, z, qx, qy, qz, qw = pose
    return compose_poses((0.0, 0.0, 0.0, -qx, -qy, -qz, qw), (-x, -y, -z, 0.0, 0.0, 0.0, 1.0))


def joint_transforms(
    links: Mapping[str, Sequence[float]], joints: Sequence[tuple[str, str]], root: str = "world"
) -> list[Transform]:
    """Each joint's child pose in its parent, from every link's pose in ``root`` (``links``; ``root``
    itself is at the identity when absent). A joint whose parent or child has no pose is left out."""
    out: list[Transform] = []
    identity = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    for parent, child in joints:
        parent_pose = identity if parent == root and parent not in links else links.get(parent)
        child_pose = links.get(child)
        if parent_pose is None or child_pose is None:
            continue
        out.append((parent, child, compose_poses(inverse_pose(parent_pose), child_pose)))
    return out


def world_poses(transforms: Sequence[Transform], root: str = "world") -> dict[str, tuple[float, ...]]:
    """Every child's pose in ``root``, composed down the tree from parent → child transforms (what
    ``joint_transforms`` undid); a transform whose parent never reaches ``root`` is left out."""
    found: dict[str, tuple[float, ...]] = {}
    todo = list(transforms)
    while todo:
        later = []
        for parent, child, pose in todo:
            if parent == root:
                found[child] = tuple(pose)
            elif parent in found:
                found[child] = compose_poses(found[parent], pose)
            else:
                later.append((parent, child, pose))
        if len(later) == len(todo):  # nothing resolved this round: those parents never reach root
            break
        todo = later
    return found
