"""The fake arm's motions whose path is the TCP's: what a controller plays for movel, movep, movec, speedl.

Pure: no asyncio, no clock. Each is a ``Motion`` of fakeur/joint_motion.py (a joint-space path over
program time), made from TCP poses or twists and turned into joints sample by sample, through the
inverse kinematics or the Jacobian the caller gives:

* ``CartesianMove`` (movel, movep): the TCP on a straight line (position interpolated, orientation
  slerped) with a trapezoidal profile along it, each sample solved by inverse kinematics near the last.
* ``ArcMove`` (movec): the TCP on the circle through three points.
* ``ToolSpeedRamp`` (speedl): the TCP twist ramped linearly to its target, joint speeds from the
  Jacobian each sample (damped near singularities).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from urdaemon.description.frames import Frame, compose, frame_of_pose, inverse, pose_of_frame
from urdaemon.fakeur.joint_motion import JOINTS, Profile, Vector, profile

__all__ = ["ArcMove", "CartesianMove", "InverseKinematics", "JointVelocity", "ToolSpeedRamp"]


def _relative_rotation(a: Frame, b: Frame) -> tuple[float, float, float]:
    """The rotation vector of aᵀ·b (the rotation from a to b, in a's frame)."""
    return pose_of_frame(compose(inverse(a), b))[3:]


InverseKinematics = Callable[[Sequence[float], Sequence[float]], Sequence[float] | None]
"""(TCP pose, joints near) → joints reaching the pose, or None if it cannot be reached."""


class CartesianMove:
    """movel: the TCP from ``start`` to ``target`` on a straight line (orientation slerped).

    The path parameter follows ``shape`` (its distance is the translation, or the rotation angle for a
    pure rotation); each sample is solved by ``solve`` near the previous sample's joints, so the arm
    keeps its configuration. A ``start_velocity`` (blending out of a moving motion) fades out in joint
    space as in ``JointMove``. ``failed`` is set once a sample has no solution (the arm then holds).
    """

    __slots__ = (
        "_axis",
        "_fade",
        "_last",
        "_last_t",
        "_move",
        "_rate",
        "_residual",
        "_shape",
        "_solve",
        "_start",
        "duration",
        "failed",
    )

    def __init__(
        self,
        start_pose: Sequence[float],
        target_pose: Sequence[float],
        shape: Profile,
        start_joints: Sequence[float],
        solve: InverseKinematics,
        start_velocity: Sequence[float] | None = None,
        fade_time: float = 0.0,
    ) -> None:
        self._start = frame_of_pose(start_pose)
        end = frame_of_pose(target_pose)
        self._move = (end[9] - self._start[9], end[10] - self._start[10], end[11] - self._start[11])
        self._axis = _relative_rotation(self._start, end)
        self._shape = shape
        self._solve = solve
        self._last = [float(v) for v in start_joints]
        self._last_t = 0.0
        self._rate = [0.0] * JOINTS
        moving = start_velocity is not None and fade_time > 0 and any(start_velocity)
        self._residual = [float(v) for v in start_velocity] if moving and start_velocity else None
        self._fade = fade_time if moving else 0.0
        self.duration = max(shape.duration, self._fade)
        self.failed = False

    def pose(self, t: float) -> tuple[float, float, float, float, float, float]:
        """The TCP pose of the straight path at ``t``."""
        shape = self._shape
        f = shape.at(t)[0] / shape.distance if shape.distance > 0 else 1.0
        ax, ay, az = self._axis
        m = compose(self._start, frame_of_pose((0.0, 0.0, 0.0, f * ax, f * ay, f * az)))
        dx, dy, dz = self._move
        s = self._start
        return pose_of_frame((*m[:9], s[9] + f * dx, s[10] + f * dy, s[11] + f * dz))

    def _path(self, t: float) -> Vector:
        """The joints on the straight path at ``t`` (solved near the previous sample)."""
        if self.failed or t == self._last_t:
            return self._last
        q = self._solve(self.pose(t), self._last)
        if q is None:
            self.failed = True
            self._rate = [0.0] * JOINTS
            return self._last
        q = [float(v) for v in q]
        h = t - self._last_t
        self._rate = [(b - a) / h for a, b in zip(self._last, q, strict=True)] if h > 0 else [0.0] * JOINTS
        self._last = q
        self._last_t = t
        return q

    def position(self, t: float) -> Vector:
        """Joint positions [rad] at ``t``."""
        q = list(self._path(t))
        residual, fade = self._residual, self._fade
        if residual is not None and t < fade and not self.failed:
            u = max(t, 0.0) / fade
            h = fade * u * (1.0 - u) * (1.0 - u)
            q = [v + r * h for v, r in zip(q, residual, strict=True)]
        return q

    def velocity(self, t: float) -> Vector:
        """Joint velocities [rad/s] at ``t``: the path's rate over the last sampled step, plus the fade."""
        if self.failed or t >= self.duration:
            return [0.0] * JOINTS
        qd = list(self._rate) if t < self._shape.duration else [0.0] * JOINTS
        residual, fade = self._residual, self._fade
        if residual is not None and t < fade:
            u = max(t, 0.0) / fade
            dh = (1.0 - u) * (1.0 - 3.0 * u)
            qd = [v + r * dh for v, r in zip(qd, residual, strict=True)]
        return qd


class ArcMove(CartesianMove):
    """movec: the TCP on the circle through ``start``, ``via`` and ``target`` (from start to target).

    ``fixed_orientation`` False (mode 0): the orientation is interpolated from start to target as in
    movel; True (mode 1): it turns with the arc, keeping its angle to the circle's tangent.
    ValueError for points on one line (no circle through them)."""

    __slots__ = ("_arc", "_center", "_fixed", "_normal", "_radius", "_u", "_w")

    def __init__(
        self,
        start_pose: Sequence[float],
        via: Sequence[float],
        target_pose: Sequence[float],
        velocity: float,
        acceleration: float,
        start_joints: Sequence[float],
        solve: InverseKinematics,
        *,
        fixed_orientation: bool = False,
        start_velocity: Sequence[float] | None = None,
        fade_time: float = 0.0,
    ) -> None:
        p0, p1, p2 = (list(map(float, p[:3])) for p in (start_pose, via, target_pose))
        a = [x - y for x, y in zip(p1, p0, strict=True)]
        b = [x - y for x, y in zip(p2, p0, strict=True)]
        n = _cross(a, b)
        nn = _dot(n, n)
        if nn < 1e-18:
            raise ValueError("the three points lie on one line: no circle through them")
        # circumcentre: p0 + (|a|²·(b × n) + |b|²·(n × a)) / (2|n|²)
        bn, na = _cross(b, n), _cross(n, a)
        aa, bb = _dot(a, a), _dot(b, b)
        center = [p0[i] + (aa * bn[i] + bb * na[i]) / (2.0 * nn) for i in range(3)]
        radius = math.dist(center, p0)
        normal = [v / math.sqrt(nn) for v in n]
        u = [(p0[i] - center[i]) / radius for i in range(3)]
        w = _cross(normal, u)
        rel = [p2[i] - center[i] for i in range(3)]
        arc = math.atan2(_dot(rel, w), _dot(rel, u)) % (2.0 * math.pi)
        self._center, self._radius, self._normal, self._u, self._w, self._arc = (
            center,
            radius,
            normal,
            u,
            w,
            arc,
        )
        self._fixed = fixed_orientation
        shape = profile(radius * arc, velocity=velocity, acceleration=acceleration)
        super().__init__(start_pose, target_pose, shape, start_joints, solve, start_velocity, fade_time)

    def pose(self, t: float) -> tuple[float, float, float, float, float, float]:
        """The TCP pose on the arc at ``t``."""
        shape = self._shape
        f = shape.at(t)[0] / shape.distance if shape.distance > 0 else 1.0
        angle = f * self._arc
        c, s_ = math.cos(angle) * self._radius, math.sin(angle) * self._radius
        point = [self._center[i] + c * self._u[i] + s_ * self._w[i] for i in range(3)]
        if self._fixed:
            nx, ny, nz = self._normal
            turn = frame_of_pose((0.0, 0.0, 0.0, nx * angle, ny * angle, nz * angle))
            m = compose(turn, self._start)  # turned about the circle's axis, in base
        else:
            ax, ay, az = self._axis
            m = compose(self._start, frame_of_pose((0.0, 0.0, 0.0, f * ax, f * ay, f * az)))
        return pose_of_frame((*m[:9], point[0], point[1], point[2]))


def _cross(a: Sequence[float], b: Sequence[float]) -> list[float]:
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _dot(a: Sequence[float], b: Sequence[float]) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


JointVelocity = Callable[[Sequence[float], Sequence[float]], Sequence[float]]
"""(joints, TCP twist) → joint velocities giving that twist."""


class ToolSpeedRamp:
    """speedl: the TCP twist from ``start_twist`` to ``target_twist`` (linear ramp), then held.

    The ramp takes the longer of |Δv|/``linear_acceleration`` and |Δω|/``angular_acceleration``.
    Joint positions are integrated sample by sample (the arm samples forward in time), each step with
    the joint velocities ``joint_velocity`` gives for the twist at the previous sample's joints.
    """

    __slots__ = ("_last", "_last_t", "_ramp", "_rate", "_solve", "_twist0", "_twist1", "duration")

    def __init__(
        self,
        start: Sequence[float],
        start_twist: Sequence[float],
        target_twist: Sequence[float],
        linear_acceleration: float,
        angular_acceleration: float,
        duration: float,
        joint_velocity: JointVelocity,
    ) -> None:
        self._twist0 = [float(v) for v in start_twist]
        self._twist1 = [float(v) for v in target_twist]
        change = [b - a for a, b in zip(self._twist0, self._twist1, strict=True)]
        linear = math.sqrt(sum(v * v for v in change[:3]))
        angular = math.sqrt(sum(v * v for v in change[3:]))
        self._ramp = max(linear / max(linear_acceleration, 1e-9), angular / max(angular_acceleration, 1e-9))
        self._solve = joint_velocity
        self._last = [float(v) for v in start]
        self._last_t = 0.0
        self._rate = [float(v) for v in joint_velocity(self._last, self._twist0)]
        self.duration = duration if duration > 0 else self._ramp

    def twist(self, t: float) -> Vector:
        """The commanded TCP twist at ``t``."""
        ramp = self._ramp
        f = 1.0 if ramp <= 0 or t >= ramp else max(t, 0.0) / ramp
        return [a + (b - a) * f for a, b in zip(self._twist0, self._twist1, strict=True)]

    def position(self, t: float) -> Vector:
        """Joint positions [rad] at ``t`` (integrated from the previous sample; ``t`` only increases)."""
        h = t - self._last_t
        if h > 0:
            # midpoint rule: the twist half-way, at the joints half-way
            middle = self.twist(self._last_t + 0.5 * h)
            rate = [float(v) for v in self._solve(self._last, middle)]
            halfway = [q + r * 0.5 * h for q, r in zip(self._last, rate, strict=True)]
            rate = [float(v) for v in self._solve(halfway, middle)]
            self._last = [q + r * h for q, r in zip(self._last, rate, strict=True)]
            self._rate = rate
            self._last_t = t
        return list(self._last)

    def velocity(self, t: float) -> Vector:
        """Joint velocities [rad/s] over the last sampled step (call after ``position``)."""
        return list(self._rate)
