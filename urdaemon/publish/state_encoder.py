"""The state messages published every robot cycle, encoded fast enough for 500 Hz: ``joint_states``
and ``tcp_pose`` (``JointStateEncoder``), and the rotation vector of ``tcp_pose``'s ``pose``
(``rotation_vector_of_quaternion``). The hot path: plain string formatting and float math."""

from __future__ import annotations

import contextlib
import json
import math
from collections.abc import Sequence

from urdaemon.model import RobotState
from urdaemon.publish.envelope import SCHEMA_VERSION

__all__ = ["JointStateEncoder", "rotation_vector_of_quaternion"]


def _floats(values: Sequence[float]) -> str:
    return ",".join([_float(v) for v in values])


class JointStateEncoder:
    """Encodes a robot's joint state as JSON fast enough for 500 Hz.

    Each message is one ``%`` format of a template built once (``%r`` gives the shortest
    round-tripping text of a float, as ``repr``); only when a value is not finite (JSON has no NaN or
    inf) does it take the slow path that writes ``null`` for it.
    """

    def __init__(self, robot: str, joint_names: Sequence[str]) -> None:
        names = json.dumps(list(joint_names))
        self._robot = json.dumps(robot)
        self._head = f'{{"v":{SCHEMA_VERSION},"robot":{self._robot},"names":{names},'
        floats = ",".join(["%r"] * len(joint_names))
        self._joints = _escape(self._head) + (
            f'"controller_time":%r,"host_time_ns":%d,"cycle":%d,"position":[{floats}],'
            f'"velocity":[{floats}],"effort":[{floats}]}}'
        )
        self._poses: dict[tuple[str, str], tuple[str, str]] = {}
        """(frame, child) → (the message's head, the whole message's ``%`` template)."""

    def encode(self, state: RobotState) -> bytes:
        """The joint_states message for ``state``."""
        positions, velocities, efforts = state.positions, state.velocities, state.efforts
        check = sum(positions) + sum(velocities) + sum(efforts) + state.controller_time
        if check - check == 0.0:  # all finite (a NaN or inf anywhere makes this NaN)
            with contextlib.suppress(TypeError):  # not as many values as joints: the slow path copes
                values = (state.controller_time, state.host_time_ns, state.cycle, *positions, *velocities)
                return (self._joints % (*values, *efforts)).encode()
        return (
            f'{self._head}"controller_time":{_float(state.controller_time)},'
            f'"host_time_ns":{state.host_time_ns},"cycle":{state.cycle},"position":[{_floats(positions)}],'
            f'"velocity":[{_floats(velocities)}],"effort":[{_floats(efforts)}]}}'
        ).encode()

    def encode_pose(self, state: RobotState, frame: str, child: str, pose: Sequence[float]) -> bytes:
        """The tcp_pose message: the robot, and the position and quaternion (x, y, z, w) of ``child``
        in ``frame``; and the same as ``pose``, [x, y, z, rx, ry, rz] with a rotation vector, as every
        pose input takes it (``rotation_vector_of_quaternion``)."""
        known = self._poses.get((frame, child))
        if known is None:
            head = (
                f'{{"v":{SCHEMA_VERSION},"robot":{self._robot},"frame":{json.dumps(frame)},'
                f'"child":{json.dumps(child)},'
            )
            template = _escape(head) + (
                '"controller_time":%r,"host_time_ns":%d,"position":[%s],"orientation":[%r,%r,%r,%r],'
                '"pose":[%s,%r,%r,%r]}'
            )
            known = self._poses[(frame, child)] = (head, template)
        head, template = known
        check = sum(pose) + state.controller_time
        if len(pose) == 7 and check - check == 0.0:
            x, y, z, qx, qy, qz, qw = pose
            position = f"{x!r},{y!r},{z!r}"  # written once, used twice
            rx, ry, rz = rotation_vector_of_quaternion(qx, qy, qz, qw)
            stamp = (state.controller_time, state.host_time_ns)
            return (template % (*stamp, position, qx, qy, qz, qw, position, rx, ry, rz)).encode()
        rotation = rotation_vector_of_quaternion(*pose[3:7]) if len(pose) == 7 else (math.nan,) * 3
        return (
            f'{head}"controller_time":{_float(state.controller_time)},"host_time_ns":{state.host_time_ns},'
            f'"position":[{_floats(pose[:3])}],"orientation":[{_floats(pose[3:7])}],'
            f'"pose":[{_floats(pose[:3])},{_floats(rotation)}]}}'
        ).encode()


def rotation_vector_of_quaternion(qx: float, qy: float, qz: float, qw: float) -> tuple[float, float, float]:
    """The rotation vector (axis times angle, rad) of a quaternion (any length), as pose inputs take it
    (``description.frames.frame_of_pose``): the angle in [0, pi], so ``q`` and ``-q`` give the same
    vector. At exactly pi (``qw`` 0) both signs of the axis are the same turn; the one whose largest
    component is positive is given, as ``description.frames.pose_of_frame`` does. Plain float math:
    ``tcp_pose`` runs it every robot cycle."""
    s = math.hypot(qx, qy, qz)
    if s == 0.0:  # no turn (and a zero quaternion has none to tell)
        return (0.0, 0.0, 0.0)
    if qw < 0.0:  # the other half of the double cover: the same turn, the angle under pi
        qx, qy, qz, qw = -qx, -qy, -qz, -qw
    elif qw == 0.0 and _largest_negative(qx, qy, qz):
        qx, qy, qz = -qx, -qy, -qz
    angle = 2.0 * math.atan2(s, qw)
    # the axis first (each part at most 1): angle / s overflows to inf for a tiny s (5e-324)
    return (qx / s * angle, qy / s * angle, qz / s * angle)


def _largest_negative(x: float, y: float, z: float) -> bool:
    """Is the component of (x, y, z) of the largest size (the first of equals) negative?"""
    ax, ay, az = abs(x), abs(y), abs(z)
    if ax >= ay and ax >= az:
        return x < 0.0
    return y < 0.0 if ay >= az else z < 0.0


def _escape(text: str) -> str:
    """``text`` as a literal part of a ``%`` template."""
    return text.replace("%", "%%")


def _float(value: float) -> str:
    # repr gives the shortest round-tripping text; JSON has no NaN/inf, so map them to null
    return repr(value) if value == value and value not in (math.inf, -math.inf) else "null"
