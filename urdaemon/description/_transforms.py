"""The fixed transforms the cell URDF is written from, in plain floats, and URDF roll-pitch-yaw.

A transform is a ``frames.Frame`` (flat, row-major rotation then translation), chained with
``frames.compose``; ``Matrix`` is its 4x4 row form, what a URDF ``<origin>`` denotes. URDF's
roll, pitch, yaw: R = Rz(yaw)·Ry(pitch)·Rx(roll). No numpy: serving builds the URDF with these.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from urdaemon.description.frames import Frame

__all__ = [
    "Matrix",
    "matrix_of",
    "rot_x",
    "rot_z",
    "rpy_of",
    "trans_x",
    "trans_z",
    "xyz_rpy",
    "xyz_rpy_matrix",
]

Matrix = tuple[
    tuple[float, float, float, float],
    tuple[float, float, float, float],
    tuple[float, float, float, float],
    tuple[float, float, float, float],
]
"""A rigid transform as four rows of a homogeneous 4x4 matrix."""


def trans_x(a: float) -> Frame:
    """Translation by ``a`` along x."""
    return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, a, 0.0, 0.0)


def trans_z(d: float) -> Frame:
    """Translation by ``d`` along z."""
    return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, d)


def rot_x(angle: float) -> Frame:
    """Rotation by ``angle`` about x."""
    c, s = math.cos(angle), math.sin(angle)
    return (1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c, 0.0, 0.0, 0.0)


def rot_z(angle: float) -> Frame:
    """Rotation by ``angle`` about z."""
    c, s = math.cos(angle), math.sin(angle)
    return (c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)


def xyz_rpy(xyz: Sequence[float], rpy: Sequence[float]) -> Frame:
    """The transform of a URDF ``<origin xyz rpy>``: T(xyz)·Rz(yaw)·Ry(pitch)·Rx(roll)."""
    roll, pitch, yaw = rpy
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return (
        cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr,
        sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr,
        -sp, cp * sr, cp * cr,
        float(xyz[0]), float(xyz[1]), float(xyz[2]),
    )  # fmt: skip


def matrix_of(f: Frame) -> Matrix:
    """The 4x4 rows of ``f``."""
    return (
        (f[0], f[1], f[2], f[9]),
        (f[3], f[4], f[5], f[10]),
        (f[6], f[7], f[8], f[11]),
        (0.0, 0.0, 0.0, 1.0),
    )


def xyz_rpy_matrix(xyz: Sequence[float], rpy: Sequence[float]) -> Matrix:
    """The 4x4 rows of a URDF ``<origin xyz rpy>``."""
    return matrix_of(xyz_rpy(xyz, rpy))


def rpy_of(m: Matrix | Any) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw of the rotation part of ``m`` (4x4 rows, ``m[i][j]``); exact to rounding
    also at pitch ±π/2."""
    # Take yaw first, undo it, then read pitch and roll off Rz(-yaw)·R = Ry(pitch)·Rx(roll).
    # Near pitch ±π/2 yaw is poorly determined, but roll is then fitted to whatever yaw was
    # chosen, so the three angles still rebuild R to rounding (the textbook formula does not).
    r0, r1, r2 = m[0], m[1], m[2]
    yaw = math.atan2(r1[0], r0[0])
    cy, sy = math.cos(yaw), math.sin(yaw)
    pitch = math.atan2(-r2[0], cy * r0[0] + sy * r1[0])
    roll = math.atan2(sy * r0[2] - cy * r1[2], cy * r1[1] - sy * r0[1])
    # adding 0.0 turns -0.0 into 0.0, which keeps "-0.0" out of the URDF text
    return (float(roll) + 0.0, float(pitch) + 0.0, float(yaw) + 0.0)
