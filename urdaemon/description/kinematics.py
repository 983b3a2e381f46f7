"""Forward kinematics for the hot paths, in plain float math (no numpy, no yourdfpy at run time).

``DhKinematics.tool_pose`` runs every robot cycle (500 Hz); ``KinematicTree.link_poses`` runs at the
TF rate for the whole cell. Poses are ``(x, y, z, qx, qy, qz, qw)`` with ``qw >= 0``.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from urdaemon.description.frames import axis_rotation, compose, frame_of_pose
from urdaemon.description.urmodels import DhParameters
from urdaemon.errors import DescriptionError

__all__ = [
    "DhJoint",
    "DhKinematics",
    "KinematicTree",
    "TreeJoint",
    "compose_poses",
    "dh_chain",
    "dh_joints",
    "quaternion_of",
]

Transform = tuple[float, float, float, float, float, float, float, float, float, float, float, float]
"""Row-major rotation r00 r01 r02 r10 r11 r12 r20 r21 r22, then translation x y z."""

_IDENTITY: Transform = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)

_FIXED, _ROTATE_Z, _ROTATE, _SLIDE = 0, 1, 2, 3


def compose_poses(a: Sequence[float], b: Sequence[float]) -> tuple[float, ...]:
    """The pose ``b`` given in the frame at pose ``a``, in ``a``'s parent frame; both, and the result,
    (x, y, z, qx, qy, qz, qw)."""
    px, py, pz, ax, ay, az, aw = a
    tx, ty, tz, bx, by, bz, bw = b
    # b's position rotated by the quaternion a: t + 2 w (u x t) + 2 u x (u x t), u = (ax, ay, az)
    cx, cy, cz = ay * tz - az * ty, az * tx - ax * tz, ax * ty - ay * tx
    dx, dy, dz = ay * cz - az * cy, az * cx - ax * cz, ax * cy - ay * cx
    return (
        px + tx + 2.0 * (aw * cx + dx),
        py + ty + 2.0 * (aw * cy + dy),
        pz + tz + 2.0 * (aw * cz + dz),
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def quaternion_of(
    r00: float, r01: float, r02: float, r10: float, r11: float, r12: float, r20: float, r21: float, r22: float
) -> tuple[float, float, float, float]:
    """(qx, qy, qz, qw) of a rotation matrix, with qw >= 0."""
    # Divide by the largest of 4w², 4x², 4y², 4z² so the square root never nears zero.
    trace = r00 + r11 + r22
    if trace > 0.0:
        s = 2.0 * math.sqrt(1.0 + trace)
        qw, qx, qy, qz = 0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s
    elif r00 > r11 and r00 > r22:
        s = 2.0 * math.sqrt(1.0 + r00 - r11 - r22)
        qw, qx, qy, qz = (r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s
    elif r11 > r22:
        s = 2.0 * math.sqrt(1.0 + r11 - r00 - r22)
        qw, qx, qy, qz = (r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s
    else:
        s = 2.0 * math.sqrt(1.0 + r22 - r00 - r11)
        qw, qx, qy, qz = (r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s
    if qw < 0.0:
        return (-qx, -qy, -qz, -qw)
    return (qx, qy, qz, qw)


DhJoint = tuple[float, float, float, float, float]
"""One standard-DH joint, ready to walk: (theta offset, d, a, cos alpha, sin alpha)."""


def dh_joints(dh: DhParameters) -> tuple[DhJoint, ...]:
    """The six joints of ``dh`` as :func:`dh_chain` walks them."""
    return tuple(
        (dh.theta[i], dh.d[i], dh.a[i], math.cos(dh.alpha[i]), math.sin(dh.alpha[i])) for i in range(6)
    )


def dh_chain(
    joints: Sequence[DhJoint],
    q: Iterable[float],
    axes: list[tuple[float, float, float]] | None = None,
    points: list[tuple[float, float, float]] | None = None,
) -> Transform:
    """The flange (tool0) in the base frame for joint positions ``q`` (rad), as a row-major Transform.

    With ``axes`` and ``points``, each joint's rotation axis and a point on it (base frame) are appended
    in order (what a Jacobian needs). Plain float math: this runs every robot cycle.
    """
    cos, sin = math.cos, math.sin
    # Columns of the running rotation: x = (xx, xy, xz), y = ..., z = ...; p is the origin.
    xx, xy, xz = 1.0, 0.0, 0.0
    yx, yy, yz = 0.0, 1.0, 0.0
    zx, zy, zz = 0.0, 0.0, 1.0
    px = py = pz = 0.0
    for (theta, d, a, ca, sa), qi in zip(joints, q, strict=True):
        if axes is not None and points is not None:
            axes.append((zx, zy, zz))
            points.append((px, py, pz))
        angle = theta + qi
        ct, st = cos(angle), sin(angle)
        # Tz(d)·Rz(angle) first: the origin moves d along z, x and y turn about z.
        px += d * zx
        py += d * zy
        pz += d * zz
        ux, uy, uz = ct * xx + st * yx, ct * xy + st * yy, ct * xz + st * yz
        vx, vy, vz = ct * yx - st * xx, ct * yy - st * xy, ct * yz - st * xz
        # Then Tx(a)·Rx(alpha): the origin moves a along the new x, y and z turn about it.
        px += a * ux
        py += a * uy
        pz += a * uz
        xx, xy, xz = ux, uy, uz
        yx, yy, yz, zx, zy, zz = (
            ca * vx + sa * zx,
            ca * vy + sa * zy,
            ca * vz + sa * zz,
            ca * zx - sa * vx,
            ca * zy - sa * vy,
            ca * zz - sa * vz,
        )
    return (xx, yx, zx, xy, yy, zy, xz, yz, zz, px, py, pz)


class DhKinematics:
    """Standard-DH forward kinematics of a 6-joint UR arm: tool0 in the controller's base frame."""

    __slots__ = ("_joints",)

    def __init__(self, dh: DhParameters) -> None:
        self._joints = dh_joints(dh)

    def tool_pose(self, q: Sequence[float]) -> tuple[float, ...]:
        """(x, y, z, qx, qy, qz, qw) of tool0 in base for joint positions ``q`` (6 values, rad)."""
        r00, r01, r02, r10, r11, r12, r20, r21, r22, px, py, pz = dh_chain(self._joints, q)
        qx, qy, qz, qw = quaternion_of(r00, r01, r02, r10, r11, r12, r20, r21, r22)
        return (px, py, pz, qx, qy, qz, qw)


class ToolOffset:
    """A TCP offset (x, y, z, rx, ry, rz in the tool0 frame) applied to tool0 poses, precomputed once."""

    __slots__ = ("_offset",)

    def __init__(self, tcp: Sequence[float]) -> None:
        r00, r01, r02, r10, r11, r12, r20, r21, r22, x, y, z = frame_of_pose(tcp)
        self._offset = (x, y, z, *quaternion_of(r00, r01, r02, r10, r11, r12, r20, r21, r22))

    def apply(self, pose: Sequence[float]) -> tuple[float, ...]:
        """(x, y, z, qx, qy, qz, qw) of the TCP for the tool0 pose ``pose`` (same layout)."""
        return compose_poses(pose, self._offset)


@dataclass(frozen=True, slots=True)
class TreeJoint:
    """One joint of a ``KinematicTree``, as precomputed from the URDF."""

    name: str
    parent: str
    child: str
    type: str
    origin: Transform
    axis: tuple[float, float, float]
    mimic: tuple[str, float, float] | None
    """(source joint, multiplier, offset), resolved to an actuated source, or None."""


class KinematicTree:
    """Poses of every link of a URDF in its root frame, for given joint positions."""

    __slots__ = ("_links", "_root", "_steps", "joints")

    def __init__(self, root: str, joints: Sequence[TreeJoint]) -> None:
        self._root = root
        self.joints: tuple[TreeJoint, ...] = tuple(joints)
        index = {root: 0}
        links = [root]
        for joint in joints:
            if joint.parent not in index:
                raise DescriptionError(f"joint {joint.name!r}: parent link {joint.parent!r} comes after it")
            if joint.child in index:
                raise DescriptionError(f"joint {joint.name!r}: link {joint.child!r} has two parents")
            index[joint.child] = len(links)
            links.append(joint.child)
        self._links: tuple[str, ...] = tuple(links)
        steps: list[tuple[int, int, int, Transform, float, float, float, str, float, float]] = []
        for joint in joints:
            kind = _FIXED
            if joint.type in ("revolute", "continuous"):
                kind = _ROTATE_Z if joint.axis == (0.0, 0.0, 1.0) else _ROTATE
            elif joint.type == "prismatic":
                kind = _SLIDE
            source, multiplier, offset = joint.name, 1.0, 0.0
            if joint.mimic is not None:
                source, multiplier, offset = joint.mimic
            ax, ay, az = joint.axis
            steps.append(
                (
                    index[joint.parent],
                    index[joint.child],
                    kind,
                    joint.origin,
                    ax,
                    ay,
                    az,
                    source,
                    multiplier,
                    offset,
                )
            )
        self._steps = tuple(steps)

    @property
    def root(self) -> str:
        """The root link."""
        return self._root

    @property
    def links(self) -> tuple[str, ...]:
        """Every link, root first, each after its parent."""
        return self._links

    @classmethod
    def from_urdf(cls, urdf: Any) -> KinematicTree:
        """The tree of a ``UrdfFacts`` or yourdfpy ``URDF`` (joints parent before child from the root)."""
        root = urdf.base_link
        if root is None:
            raise DescriptionError("the URDF has no root link (every link has a parent)")
        by_parent: dict[str, list[Any]] = {}
        for joint in urdf.robot.joints:
            by_parent.setdefault(joint.parent, []).append(joint)
        joint_map: dict[str, Any] = {j.name: j for j in urdf.robot.joints}
        ordered: list[TreeJoint] = []
        todo = deque([root])
        seen = {root}
        while todo:
            for joint in by_parent.get(todo.popleft(), ()):
                if joint.child in seen:
                    raise DescriptionError(f"joint {joint.name!r}: link {joint.child!r} is reached twice")
                seen.add(joint.child)
                todo.append(joint.child)
                ordered.append(_tree_joint(joint, joint_map))
        return cls(root, ordered)

    def link_poses(self, positions: Mapping[str, float]) -> list[tuple[str, tuple[float, ...]]]:
        """(link, (x, y, z, qx, qy, qz, qw)) of every link in the root frame; joints not given are at 0."""
        cos, sin = math.cos, math.sin
        get = positions.get
        frames: list[Transform] = [_IDENTITY] * len(self._links)
        for parent, child, kind, origin, ax, ay, az, source, multiplier, offset in self._steps:
            m = compose(frames[parent], origin)
            if kind != _FIXED:
                value = multiplier * get(source, 0.0) + offset
                if kind == _ROTATE_Z:
                    c, s = cos(value), sin(value)
                    r00, r01, r02, r10, r11, r12, r20, r21, r22, x, y, z = m
                    m = (
                        c * r00 + s * r01, c * r01 - s * r00, r02,
                        c * r10 + s * r11, c * r11 - s * r10, r12,
                        c * r20 + s * r21, c * r21 - s * r20, r22,
                        x, y, z,
                    )  # fmt: skip
                elif kind == _ROTATE:
                    m = compose(m, axis_rotation(ax, ay, az, value))
                else:
                    r00, r01, r02, r10, r11, r12, r20, r21, r22, x, y, z = m
                    dx, dy, dz = ax * value, ay * value, az * value
                    m = (
                        r00, r01, r02, r10, r11, r12, r20, r21, r22,
                        x + r00 * dx + r01 * dy + r02 * dz,
                        y + r10 * dx + r11 * dy + r12 * dz,
                        z + r20 * dx + r21 * dy + r22 * dz,
                    )  # fmt: skip
            frames[child] = m
        result: list[tuple[str, tuple[float, ...]]] = []
        for name, f in zip(self._links, frames, strict=True):
            qx, qy, qz, qw = quaternion_of(f[0], f[1], f[2], f[3], f[4], f[5], f[6], f[7], f[8])
            result.append((name, (f[9], f[10], f[11], qx, qy, qz, qw)))
        return result


def _tree_joint(joint: Any, joint_map: dict[str, Any]) -> TreeJoint:
    origin: Transform = _IDENTITY
    if joint.origin is not None:
        o = joint.origin
        origin = (
            float(o[0][0]), float(o[0][1]), float(o[0][2]),
            float(o[1][0]), float(o[1][1]), float(o[1][2]),
            float(o[2][0]), float(o[2][1]), float(o[2][2]),
            float(o[0][3]), float(o[1][3]), float(o[2][3]),
        )  # fmt: skip
    axis = (0.0, 0.0, 1.0)
    if joint.type in ("revolute", "continuous", "prismatic"):
        raw = (1.0, 0.0, 0.0) if joint.axis is None else tuple(float(v) for v in joint.axis)
        norm = math.sqrt(raw[0] ** 2 + raw[1] ** 2 + raw[2] ** 2)
        if not norm > 0.0:
            raise DescriptionError(f"joint {joint.name!r}: axis {raw} has no direction")
        axis = (raw[0] / norm + 0.0, raw[1] / norm + 0.0, raw[2] / norm + 0.0)
    mimic: tuple[str, float, float] | None = None
    if joint.mimic is not None:
        # Follow a mimic of a mimic back to the joint that really moves, composing the affine maps.
        source = joint.mimic.joint
        multiplier, offset = _mimic_factor(joint.mimic)
        hops = 0
        while source in joint_map and joint_map[source].mimic is not None:
            hops += 1
            if hops > len(joint_map):
                raise DescriptionError(f"joint {joint.name!r}: its mimic chain loops")
            inner = joint_map[source].mimic
            inner_multiplier, inner_offset = _mimic_factor(inner)
            offset = multiplier * inner_offset + offset
            multiplier *= inner_multiplier
            source = inner.joint
        mimic = (source, multiplier, offset)
    return TreeJoint(
        name=joint.name,
        parent=joint.parent,
        child=joint.child,
        type=joint.type,
        origin=origin,
        axis=axis,
        mimic=mimic,
    )


def _mimic_factor(mimic: Any) -> tuple[float, float]:
    multiplier = 1.0 if mimic.multiplier is None else float(mimic.multiplier)
    offset = 0.0 if mimic.offset is None else float(mimic.offset)
    return multiplier, offset
