"""4×4 homogeneous transforms with numpy, and URDF roll-pitch-yaw (R = Rz(yaw)·Ry(pitch)·Rx(roll))."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

__all__ = ["Matrix", "rot_x", "rot_z", "rpy_of", "trans_x", "trans_z", "xyz_rpy_matrix"]

Matrix = NDArray[np.float64]


def trans_x(a: float) -> Matrix:
    """Translation by ``a`` along x."""
    m = np.eye(4)
    m[0, 3] = a
    return m


def trans_z(d: float) -> Matrix:
    """Translation by ``d`` along z."""
    m = np.eye(4)
    m[2, 3] = d
    return m


def rot_x(angle: float) -> Matrix:
    """Rotation by ``angle`` about x."""
    c, s = math.cos(angle), math.sin(angle)
    m = np.eye(4)
    m[1, 1], m[1, 2], m[2, 1], m[2, 2] = c, -s, s, c
    return m


def rot_z(angle: float) -> Matrix:
    """Rotation by ``angle`` about z."""
    c, s = math.cos(angle), math.sin(angle)
    m = np.eye(4)
    m[0, 0], m[0, 1], m[1, 0], m[1, 1] = c, -s, s, c
    return m


def xyz_rpy_matrix(xyz: tuple[float, float, float], rpy: tuple[float, float, float]) -> Matrix:
    """The transform of a URDF ``<origin xyz rpy>``."""
    roll, pitch, yaw = rpy
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    m = np.eye(4)
    m[0, :3] = (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr)
    m[1, :3] = (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr)
    m[2, :3] = (-sp, cp * sr, cp * cr)
    m[:3, 3] = xyz
    return m


def rpy_of(m: Matrix) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw of the rotation part of ``m``; exact to rounding also at pitch ±π/2."""
    # Take yaw first, undo it, then read pitch and roll off Rz(-yaw)·R = Ry(pitch)·Rx(roll).
    # Near pitch ±π/2 yaw is poorly determined, but roll is then fitted to whatever yaw was
    # chosen, so the three angles still rebuild R to rounding (the textbook formula does not).
    yaw = math.atan2(m[1, 0], m[0, 0])
    cy, sy = math.cos(yaw), math.sin(yaw)
    pitch = math.atan2(-m[2, 0], cy * m[0, 0] + sy * m[1, 0])
    roll = math.atan2(sy * m[0, 2] - cy * m[1, 2], cy * m[1, 1] - sy * m[0, 1])
    # adding 0.0 turns -0.0 into 0.0, which keeps "-0.0" out of the URDF text
    return (float(roll) + 0.0, float(pitch) + 0.0, float(yaw) + 0.0)
