"""Rigid-body dynamics of a UR arm from UR's published link inertials: M(q), c(q, q'), g(q), τ, q''.

Pure, plain float math (no numpy: the fake's direct torque mode runs the forward dynamics every
controller cycle, ~0.3 ms at 500 Hz, where numpy's per-call cost on 3-vectors came to ~3 ms). Not on
the daemon's hot path: the fake controller's dynamics builtins and its direct torque mode use it.
The facts are the model data's ``links`` (``resources/ur/<model>.yaml``: mass, centre of mass,
inertia about it, per link, from UR's ROS 2 description; ``resources/ur/README.md`` names the
source). Each link's inertial is given in its URDF link frame, which is the frame
``calibration.joint_origins`` places for the arm's (calibrated) DH: link i+1 = link i · origin_i ·
Rz(q_i). The base link is fixed and carries no joint load.

Conventions (UR's): joint torques in N·m, joint order shoulder_pan … wrist_3; the gravity vector as
``set_gravity`` takes it, the acceleration the base feels, pointing *up* (``[0, 0, 9.82]``), in the
base frame; a payload ``(mass, cog, inertia)`` as ``set_target_payload`` takes it: the centre of
gravity in the tool flange frame (tool0) and the inertia ``[Ixx, Iyy, Izz, Ixy, Ixz, Iyz]`` about the
centre of gravity, in axes aligned with tool0. The payload is rigidly added to wrist_3_link.

* ``mass_matrix``: the joint-space inertia matrix (rows) as a sum over links of m Jvᵀ Jv + Jωᵀ I Jω (the
  links' centre-of-mass Jacobians), symmetric positive definite.
* ``inverse_dynamics``: recursive Newton–Euler in the base frame; ``coriolis`` is it with q'' = 0
  and no gravity, ``gravity_torques`` with q' = q'' = 0.
* ``forward_dynamics``: q'' = M⁻¹ (τ − c − g).
* ``jacobian_derivative``: dJ/dt of the TCP's geometric Jacobian (rows vx vy vz wx wy wz, base frame).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from urdaemon.description._transforms import xyz_rpy
from urdaemon.description.calibration import TOOL0_RPY, joint_origins
from urdaemon.description.frames import Frame, compose, frame_of_pose, rotate
from urdaemon.description.urmodels import UR_LINKS, DhParameters, LinkInertial, UrModel

__all__ = ["ArmDynamics", "Payload", "cholesky_solve", "inertia_matrix"]

Vec = tuple[float, float, float]
Sym = tuple[float, float, float, float, float, float, float, float, float]
"""A 3x3 matrix, row-major (inertia tensors: symmetric)."""
Matrix6 = list[list[float]]
"""A 6x6 matrix as rows."""
_ZERO: Vec = (0.0, 0.0, 0.0)
_ZEROS6 = (0.0,) * 6


@dataclass(frozen=True, slots=True)
class Payload:
    """A payload on the tool flange, as ``set_target_payload`` gives it (kg, m in tool0, kg·m²)."""

    mass: float = 0.0
    cog: tuple[float, float, float] = (0.0, 0.0, 0.0)
    inertia: tuple[float, float, float, float, float, float] = (0.0,) * 6
    """(Ixx, Iyy, Izz, Ixy, Ixz, Iyz) about the centre of gravity, axes of tool0."""

    @classmethod
    def of(cls, mass: float, cog: Sequence[float], inertia: Sequence[float]) -> Payload:
        """A payload from plain sequences (3 and 6 numbers)."""
        c = tuple(float(v) for v in cog)
        i = tuple(float(v) for v in inertia)
        if len(c) != 3 or len(i) != 6:
            raise ValueError(f"a payload needs 3 cog and 6 inertia values, got {len(c)} and {len(i)}")
        return cls(float(mass), (c[0], c[1], c[2]), (i[0], i[1], i[2], i[3], i[4], i[5]))


def inertia_matrix(values: Sequence[float]) -> Sym:
    """The symmetric 3x3 tensor (row-major) of (Ixx, Iyy, Izz, Ixy, Ixz, Iyz)."""
    ixx, iyy, izz, ixy, ixz, iyz = (float(v) for v in values)
    return (ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz)


# ---- 3-vectors and 3x3 matrices as tuples -----------------------------------------------------------


def _cross(a: Sequence[float], b: Sequence[float]) -> Vec:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _add(a: Sequence[float], b: Sequence[float]) -> Vec:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def _sub(a: Sequence[float], b: Sequence[float]) -> Vec:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _scale(a: Sequence[float], k: float) -> Vec:
    return (a[0] * k, a[1] * k, a[2] * k)


def _dot(a: Sequence[float], b: Sequence[float]) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _apply(m: Sequence[float], v: Sequence[float]) -> Vec:
    return (
        m[0] * v[0] + m[1] * v[1] + m[2] * v[2],
        m[3] * v[0] + m[4] * v[1] + m[5] * v[2],
        m[6] * v[0] + m[7] * v[1] + m[8] * v[2],
    )


def _turned(r: Sequence[float], m: Sequence[float]) -> Sym:
    """R · M · Rᵀ (R: the rotation part of a Frame or a 9-tuple)."""
    rm = [sum(r[3 * i + k] * m[3 * k + j] for k in range(3)) for i in range(3) for j in range(3)]
    out = [sum(rm[3 * i + k] * r[3 * j + k] for k in range(3)) for i in range(3) for j in range(3)]
    return (out[0], out[1], out[2], out[3], out[4], out[5], out[6], out[7], out[8])


def _point_mass(m: float, r: Sequence[float]) -> Sym:
    """m (|r|² 1 − r rᵀ): a point mass's inertia about a point ``r`` away (parallel axes)."""
    x, y, z = r[0], r[1], r[2]
    return (
        m * (y * y + z * z), -m * x * y, -m * x * z,
        -m * x * y, m * (x * x + z * z), -m * y * z,
        -m * x * z, -m * y * z, m * (x * x + y * y),
    )  # fmt: skip


def _sum9(*ms: Sequence[float]) -> Sym:
    out = [sum(m[k] for m in ms) for k in range(9)]
    return (out[0], out[1], out[2], out[3], out[4], out[5], out[6], out[7], out[8])


def _z_turn(q: float) -> Frame:
    c, s = math.cos(q), math.sin(q)
    return (c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)


def cholesky_solve(m: Sequence[Sequence[float]], b: Sequence[float]) -> list[float]:
    """x with m x = b for a symmetric positive definite m (Cholesky); ValueError if it is not."""
    n = len(b)
    low = [[0.0] * n for _ in range(n)]
    for i in range(n):
        for j in range(i + 1):
            s = m[i][j] - sum(low[i][k] * low[j][k] for k in range(j))
            if i == j:
                if not s > 0.0:
                    raise ValueError("the matrix is not positive definite")
                low[i][i] = math.sqrt(s)
            else:
                low[i][j] = s / low[j][j]
    y = [0.0] * n
    for i in range(n):
        y[i] = (b[i] - sum(low[i][k] * y[k] for k in range(i))) / low[i][i]
    x = [0.0] * n
    for i in range(n - 1, -1, -1):
        x[i] = (y[i] - sum(low[k][i] * x[k] for k in range(i + 1, n))) / low[i][i]
    return x


# ---- the arm ----------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Body:
    """One moving link's inertial in its link frame: mass, centre of mass, inertia about it."""

    mass: float
    com: Vec
    inertia: Sym


def _body(link: LinkInertial) -> _Body:
    tensor: Sym = (0.0,) * 9
    if link.inertia is not None:
        tensor = _turned(xyz_rpy((0.0, 0.0, 0.0), link.center_of_mass_rpy), inertia_matrix(link.inertia))
    c = link.center_of_mass
    return _Body(link.mass, (c[0], c[1], c[2]), tensor)


def _combine(body: _Body, tool0: Frame, payload: Payload) -> _Body:
    """``body`` (wrist_3_link) with ``payload`` rigidly added (parallel-axis theorem, link frame)."""
    if payload.mass <= 0.0:
        return body
    cog = _add(tool0[9:12], rotate(tool0, payload.cog))
    mass = body.mass + payload.mass
    com = _scale(_add(_scale(body.com, body.mass), _scale(cog, payload.mass)), 1.0 / mass)
    total = _sum9(
        body.inertia,
        _point_mass(body.mass, _sub(body.com, com)),
        _turned(tool0, inertia_matrix(payload.inertia)),
        _point_mass(payload.mass, _sub(cog, com)),
    )
    return _Body(mass, com, total)


@dataclass(frozen=True, slots=True)
class _Pose:
    """Where the moving links are at one q (base frame), per joint i (link i+1)."""

    axes: tuple[Vec, ...]
    """Joint i's axis (z of link i+1)."""
    origins: tuple[Vec, ...]
    """Joint i's origin."""
    coms: tuple[Vec, ...]
    """Link i+1's centre of mass."""
    inertias: tuple[Sym, ...]
    """Link i+1's inertia about its centre of mass, base axes."""
    tool0: Frame
    """tool0 in base."""


class ArmDynamics:
    """Dynamics of one UR arm (its model's inertials on its DH), with a payload on the flange."""

    __slots__ = ("_bodies", "_origins", "_payload_key", "_tool0", "_with_payload")

    def __init__(self, model: UrModel, dh: DhParameters) -> None:
        chain = joint_origins(dh)
        self._origins: tuple[Frame, ...] = tuple(_frame(o.matrix) for o in chain.joints)
        self._tool0: Frame = compose(_frame(chain.flange.matrix), xyz_rpy((0.0, 0.0, 0.0), TOOL0_RPY))
        """tool0 in wrist_3_link."""
        self._bodies = tuple(_body(model.links[name]) for name in UR_LINKS[1:])
        self._payload_key: tuple[object, ...] = ()
        self._with_payload = self._bodies

    def _bodies_for(self, payload: Payload | None) -> tuple[_Body, ...]:
        """The six moving bodies, wrist_3_link carrying ``payload`` (the last one kept)."""
        if payload is None or payload.mass <= 0.0:
            return self._bodies
        key = (payload.mass, payload.cog, payload.inertia)
        if key != self._payload_key:
            last = _combine(self._bodies[5], self._tool0, payload)
            self._with_payload = (*self._bodies[:5], last)
            self._payload_key = key
        return self._with_payload

    def _pose(self, q: Sequence[float], bodies: tuple[_Body, ...]) -> _Pose:
        frame: Frame = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
        axes: list[Vec] = []
        origins: list[Vec] = []
        coms: list[Vec] = []
        inertias: list[Sym] = []
        for i in range(6):
            frame = compose(compose(frame, self._origins[i]), _z_turn(float(q[i])))
            origin = (frame[9], frame[10], frame[11])
            axes.append((frame[2], frame[5], frame[8]))
            origins.append(origin)
            coms.append(_add(origin, rotate(frame, bodies[i].com)))
            inertias.append(_turned(frame, bodies[i].inertia))
        return _Pose(tuple(axes), tuple(origins), tuple(coms), tuple(inertias), compose(frame, self._tool0))

    # ---- the equations of motion -----------------------------------------------------------------

    def mass_matrix(self, q: Sequence[float], payload: Payload | None = None) -> Matrix6:
        """M(q), 6x6 rows (kg·m²): Σ m Jvᵀ Jv + Jωᵀ I Jω over the moving links' centres of mass."""
        bodies = self._bodies_for(payload)
        pose = self._pose(q, bodies)
        m = [[0.0] * 6 for _ in range(6)]
        for k in range(6):
            mass, com, inertia = bodies[k].mass, pose.coms[k], pose.inertias[k]
            linear = [_cross(pose.axes[i], _sub(com, pose.origins[i])) for i in range(k + 1)]
            turned = [_apply(inertia, pose.axes[i]) for i in range(k + 1)]
            for i in range(k + 1):
                for j in range(i + 1):
                    value = mass * _dot(linear[i], linear[j]) + _dot(pose.axes[i], turned[j])
                    m[i][j] += value
        for i in range(6):
            for j in range(i):
                m[j][i] = m[i][j]
        return m

    def inverse_dynamics(
        self,
        q: Sequence[float],
        qd: Sequence[float],
        qdd: Sequence[float],
        gravity: Sequence[float] = _ZERO,
        payload: Payload | None = None,
    ) -> list[float]:
        """τ = M q'' + c(q, q') + g(q) (N·m): recursive Newton–Euler in the base frame, the base
        accelerating at ``gravity`` (pointing up: what holds the arm up against the earth's pull)."""
        bodies = self._bodies_for(payload)
        pose = self._pose(q, bodies)
        w: Vec = _ZERO
        dw: Vec = _ZERO
        a: Vec = (float(gravity[0]), float(gravity[1]), float(gravity[2]))
        previous: Vec = _ZERO
        forces: list[Vec] = []
        moments: list[Vec] = []
        for i in range(6):
            z, p = pose.axes[i], pose.origins[i]
            step = _sub(p, previous)  # the joint origin, carried on the previous link
            a = _add(a, _add(_cross(dw, step), _cross(w, _cross(w, step))))
            rate = float(qd[i])
            dw = _add(dw, _add(_scale(z, float(qdd[i])), _scale(_cross(w, z), rate)))
            w = _add(w, _scale(z, rate))
            r = _sub(pose.coms[i], p)
            a_com = _add(a, _add(_cross(dw, r), _cross(w, _cross(w, r))))
            inertia = pose.inertias[i]
            forces.append(_scale(a_com, bodies[i].mass))
            moments.append(_add(_apply(inertia, dw), _cross(w, _apply(inertia, w))))
            previous = p
        tau = [0.0] * 6
        f: Vec = _ZERO
        n: Vec = _ZERO
        for i in range(5, -1, -1):
            p = pose.origins[i]
            outer = _sub(pose.origins[i + 1], p) if i < 5 else _ZERO  # where the outer link pulls
            n = _add(_add(moments[i], n), _add(_cross(_sub(pose.coms[i], p), forces[i]), _cross(outer, f)))
            f = _add(forces[i], f)
            tau[i] = _dot(pose.axes[i], n)
        return tau

    def coriolis(
        self, q: Sequence[float], qd: Sequence[float], payload: Payload | None = None
    ) -> list[float]:
        """c(q, q') (N·m): the Coriolis and centrifugal torques, C(q, q')·q'."""
        return self.inverse_dynamics(q, qd, _ZEROS6, _ZERO, payload)

    def gravity_torques(
        self, q: Sequence[float], gravity: Sequence[float], payload: Payload | None = None
    ) -> list[float]:
        """g(q) (N·m): the torques that hold the arm still against gravity."""
        return self.inverse_dynamics(q, _ZEROS6, _ZEROS6, gravity, payload)

    def forward_dynamics(
        self,
        q: Sequence[float],
        qd: Sequence[float],
        tau: Sequence[float],
        gravity: Sequence[float],
        payload: Payload | None = None,
    ) -> list[float]:
        """q'' (rad/s²) under joint torques ``tau``: M⁻¹ (τ − c(q, q') − g(q))."""
        bias = self.inverse_dynamics(q, qd, _ZEROS6, gravity, payload)
        rhs = [float(t) - b for t, b in zip(tau, bias, strict=True)]
        return cholesky_solve(self.mass_matrix(q, payload), rhs)

    def linear_momentum(
        self, q: Sequence[float], qd: Sequence[float], payload: Payload | None = None
    ) -> float:
        """kg·m/s: the norm of the arm's Cartesian linear momentum Σ m v over the moving links' centres of
        mass (the payload with the last link), what RTDE's ``actual_momentum`` reports."""
        bodies = self._bodies_for(payload)
        pose = self._pose(q, bodies)
        total = _ZERO
        for k in range(6):
            com = pose.coms[k]
            v = _ZERO
            for i in range(k + 1):
                v = _add(v, _scale(_cross(pose.axes[i], _sub(com, pose.origins[i])), float(qd[i])))
            total = _add(total, _scale(v, bodies[k].mass))
        return math.sqrt(_dot(total, total))

    # ---- kinematics the dynamics share -------------------------------------------------------------

    def jacobian(self, q: Sequence[float], tcp: Sequence[float] = _ZEROS6) -> Matrix6:
        """The TCP's geometric Jacobian (6x6 rows vx vy vz wx wy wz in base), from the link frames."""
        pose = self._pose(q, self._bodies)
        point = _tcp_point(pose, tcp)
        columns = [(*_cross(z, _sub(point, o)), *z) for z, o in zip(pose.axes, pose.origins, strict=True)]
        return [[columns[j][i] for j in range(6)] for i in range(6)]

    def jacobian_derivative(
        self, q: Sequence[float], qd: Sequence[float], tcp: Sequence[float] = _ZEROS6
    ) -> Matrix6:
        """dJ/dt at (q, q'): the time derivative of :meth:`jacobian` along q' (6x6, same layout).

        Column i: ż_i = ω_(i-1) × z_i, with ω_(i-1) the angular velocity of the link joint i sits on,
        and d/dt [z_i × (p − o_i)] = ż_i × (p − o_i) + z_i × (ṗ − ȯ_i)."""
        pose = self._pose(q, self._bodies)
        point = _tcp_point(pose, tcp)
        axes, origins = pose.axes, pose.origins
        rates = [float(v) for v in qd]
        point_speed = _ZERO
        for k in range(6):
            point_speed = _add(point_speed, _scale(_cross(axes[k], _sub(point, origins[k])), rates[k]))
        w = _ZERO
        columns = []
        for i in range(6):
            origin_speed = _ZERO
            for k in range(i):
                origin_speed = _add(
                    origin_speed, _scale(_cross(axes[k], _sub(origins[i], origins[k])), rates[k])
                )
            dz = _cross(w, axes[i])
            linear = _add(
                _cross(dz, _sub(point, origins[i])), _cross(axes[i], _sub(point_speed, origin_speed))
            )
            columns.append((*linear, *dz))
            w = _add(w, _scale(axes[i], rates[i]))
        return [[columns[j][i] for j in range(6)] for i in range(6)]

    def tool0(self, q: Sequence[float]) -> Frame:
        """tool0 in the base frame (equals the DH forward kinematics)."""
        return self._pose(q, self._bodies).tool0


def _tcp_point(pose: _Pose, tcp: Sequence[float]) -> Vec:
    frame = compose(pose.tool0, frame_of_pose(tcp))
    return (frame[9], frame[10], frame[11])


def _frame(m: Sequence[Sequence[float]]) -> Frame:
    """The Frame of a 4x4 matrix given as rows."""
    return (
        m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2],
        m[0][3], m[1][3], m[2][3],
    )  # fmt: skip
