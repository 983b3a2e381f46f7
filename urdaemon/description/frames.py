"""Rigid frames as flat tuples, and UR poses (x, y, z, rx, ry, rz: a rotation vector): one definition
for the forward and inverse kinematics, the fake's motions and its URScript pose builtins.

Pure and allocation-light (tuples, ``math``): these run every controller cycle in the fake.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

__all__ = [
    "IDENTITY",
    "Frame",
    "Pose",
    "axis_rotation",
    "compose",
    "frame_of_pose",
    "inverse",
    "pose_of_frame",
    "rotate",
    "rotation_vector",
]

Frame = tuple[float, float, float, float, float, float, float, float, float, float, float, float]
"""Row-major rotation r00 r01 r02 r10 r11 r12 r20 r21 r22, then translation x y z."""
Pose = tuple[float, float, float, float, float, float]
IDENTITY: Frame = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)


def frame_of_pose(pose: Sequence[float] | Any) -> Frame:
    """The frame of a UR pose (x, y, z, rx, ry, rz) (Rodrigues)."""
    x, y, z, rx, ry, rz = pose
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if angle < 1e-300:
        return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, float(x), float(y), float(z))
    ux, uy, uz = rx / angle, ry / angle, rz / angle
    c, s = math.cos(angle), math.sin(angle)
    t = 1.0 - c
    return (
        t * ux * ux + c, t * ux * uy - s * uz, t * ux * uz + s * uy,
        t * ux * uy + s * uz, t * uy * uy + c, t * uy * uz - s * ux,
        t * ux * uz - s * uy, t * uy * uz + s * ux, t * uz * uz + c,
        float(x), float(y), float(z),
    )  # fmt: skip


def pose_of_frame(f: Frame) -> Pose:
    """The UR pose (x, y, z, rx, ry, rz) of a frame; the rotation angle is in [0, pi]."""
    rx, ry, rz = rotation_vector(f[0], f[1], f[2], f[3], f[4], f[5], f[6], f[7], f[8])
    return (f[9], f[10], f[11], rx, ry, rz)


def rotation_vector(
    r00: float, r01: float, r02: float, r10: float, r11: float, r12: float, r20: float, r21: float, r22: float
) -> tuple[float, float, float]:
    """Rotation vector of a rotation matrix, accurate at every angle including near pi."""
    vx, vy, vz = 0.5 * (r21 - r12), 0.5 * (r02 - r20), 0.5 * (r10 - r01)
    s = math.sqrt(vx * vx + vy * vy + vz * vz)
    c = 0.5 * (r00 + r11 + r22 - 1.0)
    angle = math.atan2(s, c)
    if c > -0.5:
        # sin(angle) is accurate here (angle below 2pi/3): v = sin(angle) * axis.
        scale = angle / s if s > 1e-300 else 1.0
        return (vx * scale, vy * scale, vz * scale)
    # Near pi: read the axis off the symmetric part (1 - c) * u u^T, largest diagonal first.
    d = 1.0 - c
    xx, yy, zz = (r00 - c) / d, (r11 - c) / d, (r22 - c) / d
    if xx >= yy and xx >= zz:
        ux = math.sqrt(max(xx, 0.0))
        uy, uz = (r01 + r10) / (2.0 * d * ux), (r02 + r20) / (2.0 * d * ux)
    elif yy >= zz:
        uy = math.sqrt(max(yy, 0.0))
        ux, uz = (r01 + r10) / (2.0 * d * uy), (r12 + r21) / (2.0 * d * uy)
    else:
        uz = math.sqrt(max(zz, 0.0))
        ux, uy = (r02 + r20) / (2.0 * d * uz), (r12 + r21) / (2.0 * d * uz)
    if ux * vx + uy * vy + uz * vz < 0.0:
        ux, uy, uz = -ux, -uy, -uz
    norm = math.sqrt(ux * ux + uy * uy + uz * uz)
    return (ux * angle / norm, uy * angle / norm, uz * angle / norm)


def compose(a: Frame, b: Frame) -> Frame:
    """a · b: the frame b expressed in a's parent."""
    a00, a01, a02, a10, a11, a12, a20, a21, a22, ax, ay, az = a
    b00, b01, b02, b10, b11, b12, b20, b21, b22, bx, by, bz = b
    return (
        a00 * b00 + a01 * b10 + a02 * b20,
        a00 * b01 + a01 * b11 + a02 * b21,
        a00 * b02 + a01 * b12 + a02 * b22,
        a10 * b00 + a11 * b10 + a12 * b20,
        a10 * b01 + a11 * b11 + a12 * b21,
        a10 * b02 + a11 * b12 + a12 * b22,
        a20 * b00 + a21 * b10 + a22 * b20,
        a20 * b01 + a21 * b11 + a22 * b21,
        a20 * b02 + a21 * b12 + a22 * b22,
        ax + a00 * bx + a01 * by + a02 * bz,
        ay + a10 * bx + a11 * by + a12 * bz,
        az + a20 * bx + a21 * by + a22 * bz,
    )  # fmt: skip


def inverse(f: Frame) -> Frame:
    """The inverse of a rigid frame."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22, x, y, z = f
    return (
        r00, r10, r20, r01, r11, r21, r02, r12, r22,
        -(r00 * x + r10 * y + r20 * z), -(r01 * x + r11 * y + r21 * z), -(r02 * x + r12 * y + r22 * z),
    )  # fmt: skip


def axis_rotation(x: float, y: float, z: float, angle: float) -> Frame:
    """The frame of a rotation by ``angle`` about the unit axis (x, y, z) (Rodrigues), no translation:
    a revolute joint's motion."""
    c, s = math.cos(angle), math.sin(angle)
    t = 1.0 - c
    return (
        t * x * x + c, t * x * y - s * z, t * x * z + s * y,
        t * x * y + s * z, t * y * y + c, t * y * z - s * x,
        t * x * z - s * y, t * y * z + s * x, t * z * z + c,
        0.0, 0.0, 0.0,
    )  # fmt: skip


def rotate(f: Frame, v: Sequence[float]) -> tuple[float, float, float]:
    """The vector ``v`` turned by ``f``'s rotation (its translation left out)."""
    x, y, z = v[0], v[1], v[2]
    return (
        f[0] * x + f[1] * y + f[2] * z,
        f[3] * x + f[4] * y + f[5] * z,
        f[6] * x + f[7] * y + f[8] * z,
    )
