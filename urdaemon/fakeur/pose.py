"""Where the fake arm's tool is: the flange and TCP poses of its joints, as UR reports them (``TcpPoses``).

Pure: forward kinematics of the arm's calibrated DH model, each pose kept for the joint values (and
TCP offset) it was computed for: one RTDE package asks for it twice (actual and target TCP pose) and
several clients may each ask once per cycle. ``FakeArm.tcp_pose``/``actual_tcp_pose`` (fakeur/fake_arm.py)
read it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from urdaemon.description.frames import Pose, compose, frame_of_pose, pose_of_frame
from urdaemon.description.kinematics import DhKinematics

__all__ = ["TcpPoses"]


class TcpPoses:
    """The flange (tool0) and TCP poses of one arm, each kept for the values it was computed for."""

    __slots__ = ("_flange", "_kinematics", "_tcp")

    def __init__(self, kinematics: DhKinematics) -> None:
        self._kinematics = kinematics
        self._flange: tuple[tuple[float, ...], Pose] | None = None
        """The last flange pose and the joint values it is for."""
        self._tcp: tuple[tuple[Pose, tuple[float, ...]], Pose] | None = None
        """The last TCP pose and the flange pose and offset it is for."""

    def flange(self, q: Sequence[float]) -> Pose:
        """tool0 pose in the base frame at joints ``q``: x, y, z and a rotation vector."""
        key = tuple(q)
        cached = self._flange
        if cached is not None and cached[0] == key:
            return cached[1]
        x, y, z, qx, qy, qz, qw = self._kinematics.tool_pose(key)
        pose = (x, y, z, *_rotation_vector(qx, qy, qz, qw))
        self._flange = (key, pose)
        return pose

    def tcp(self, q: Sequence[float], offset: Sequence[float]) -> Pose:
        """The TCP pose at joints ``q``: the flange pose with the TCP ``offset`` applied."""
        flange = self.flange(q)
        if not any(offset):
            return flange
        cached = self._tcp
        key = (flange, tuple(offset))
        if cached is not None and cached[0] == key:
            return cached[1]
        pose = pose_of_frame(compose(frame_of_pose(flange), frame_of_pose(offset)))
        self._tcp = (key, pose)
        return pose


def _rotation_vector(qx: float, qy: float, qz: float, qw: float) -> tuple[float, float, float]:
    """Axis-angle (rotation vector) of a unit quaternion."""
    norm = math.sqrt(qx * qx + qy * qy + qz * qz)
    if norm < 1e-12:
        return (0.0, 0.0, 0.0)
    angle = 2.0 * math.atan2(norm, qw)
    scale = angle / norm
    return (qx * scale, qy * scale, qz * scale)
