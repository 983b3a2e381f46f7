"""Inverse kinematics and the Jacobian of a UR arm, on its calibrated kinematics.

``UrKinematics(model, dh)`` solves in two stages: the closed-form UR solution on the model's nominal
DH gives up to eight branches, then Newton steps (damped least squares) on the calibrated DH (what
``DhKinematics`` computes) bring each branch onto the calibrated arm to 1e-10 m and 1e-10 rad.

Conventions (URScript's): poses are ``(x, y, z, rx, ry, rz)`` in the controller's base frame, metres
and a rotation vector (axis times angle, rad); ``tcp`` is the flange -> TCP pose (``set_tcp``), the
flange being tool0 (the DH tool frame); joint values are in rad, shoulder_pan ... wrist_3. A twist is
``(vx, vy, vz, wx, wy, wz)``: the TCP point's velocity and the angular velocity, both in base.

The closed-form stage and its branches are ur_closed_form.py's; the named configurations
configurations.py's.

In slices: ``nearest_steps`` (and ``nearest_in_steps``) are generators that yield after each bounded
chunk of work (one Newton evaluation: the calibrated chain, its error and one damped step, ~10-30 µs)
and return what ``nearest`` returns; ``nearest`` runs one to the end (``run_steps``). The event loop
drives them between robot cycles (runtime/pose_goals.py, control/linear.py).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, NamedTuple

from urdaemon.description.configurations import Configuration, named_configuration, nearest_singularity
from urdaemon.description.dls import damped_step6
from urdaemon.description.frames import (
    Frame,
    Pose,
    compose,
    frame_of_pose,
    inverse,
    pose_of_frame,
    rotation_vector,
)
from urdaemon.description.ik_types import Joints, Steps, Vector, run_steps
from urdaemon.description.kinematics import dh_chain, dh_joints
from urdaemon.description.ur_closed_form import UrClosedForm
from urdaemon.description.urmodels import DhParameters, UrModel
from urdaemon.errors import DescriptionError

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

__all__ = [
    "Frame",
    "IkSolution",
    "Pose",
    "UrKinematics",
    "frame_of_pose",
    "pose_of_frame",
    "twist_error",
]

_TAU = 2.0 * math.pi
_ZERO_SEED: Joints = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
_SLOW_STEPS = 3
"""Newton gives up after this many steps that do not halve the error (linear convergence: no solution)."""
_NEWTON_TOLERANCE = 1e-11
"""Newton stops below this (m and rad): ten times under get_inverse_kin's default maxPositionError."""
_NEWTON_EVALUATIONS = 30
_CONTINUATION_STEPS = 8
_WAYPOINT_TOLERANCE = 1e-9
_WARM_START = 0.1
"""When qnear is this near (rad, joint distance) a branch's nominal solution, Newton starts from qnear."""
_NEARER_MARGIN = 0.05
"""Nominal branches this much (rad, joint distance) farther than the best refined one are refined too."""


class IkSolution(NamedTuple):
    """One inverse-kinematics solution: its branch (``SHOULDER | WRIST | ELBOW`` bits, ur_closed_form.py)
    and joints."""

    branch: int
    q: Joints


class _Chain(NamedTuple):
    """Forward kinematics with what the Jacobian needs: the TCP frame, each joint's axis and a point on it."""

    frame: Frame
    axes: tuple[tuple[float, float, float], ...]
    points: tuple[tuple[float, float, float], ...]


class UrKinematics:
    """Forward and inverse kinematics and the Jacobian of one UR arm with its calibration.

    ``model`` gives the nominal DH (the closed-form stage) and the joint limits; ``dh`` is the arm's
    calibrated DH (default: the nominal one); ``bounds`` (lower, upper per joint), when given, replace
    the model's joint limits (a cell's narrower ``joint_limits``): each joint's 2pi shift is chosen
    within them and a solution outside them is dropped, so another branch may answer. Every method
    takes ``tcp``, the flange -> TCP pose (default: none, i.e. poses are of the flange, tool0)."""

    __slots__ = ("_a2", "_a3", "_calibrated", "_closed_form", "_d5", "_joints", "_lower", "_upper")

    dof: int = 6
    """Six joints, shoulder_pan ... wrist_3 (``ArmKinematics``)."""
    branches: bool = True
    """Named configurations apply (``configuration_of``, ``nearest_in``)."""

    def __init__(
        self,
        model: UrModel,
        dh: DhParameters | None = None,
        bounds: tuple[Sequence[float], Sequence[float]] | None = None,
    ) -> None:
        nominal = model.dh
        real = nominal if dh is None else dh
        self._calibrated = real != nominal
        self._closed_form = UrClosedForm(model, self._calibrated)
        self._a2, self._a3, self._d5 = nominal.a[1], nominal.a[2], nominal.d[4]
        self._joints = dh_joints(real)
        self._lower = tuple(-math.inf if j.min_position is None else j.min_position for j in model.joints)
        self._upper = tuple(math.inf if j.max_position is None else j.max_position for j in model.joints)
        if bounds is not None:
            lower, upper = tuple(float(v) for v in bounds[0]), tuple(float(v) for v in bounds[1])
            if len(lower) != 6 or len(upper) != 6:
                raise DescriptionError(f"model {model.model!r}: bounds for {len(lower)} joints, not 6")
            self._lower, self._upper = lower, upper

    # ---- public API ----------------------------------------------------------------------------

    def forward(self, q: Vector, tcp: Vector | None = None) -> Pose:
        """The TCP pose for joints ``q`` (URScript ``get_forward_kin(q, tcp)``)."""
        frame = self._frame(q)
        if tcp is not None:
            frame = compose(frame, frame_of_pose(tcp))
        return pose_of_frame(frame)

    def solutions(
        self,
        pose: Vector,
        tcp: Vector | None = None,
        qnear: Vector | None = None,
        max_position_error: float = 1e-10,
        max_orientation_error: float = 1e-10,
    ) -> list[IkSolution]:
        """Every branch that reaches ``pose`` within the limits, in branch order.

        Each joint is the 2pi-shift of its value that lies within the joint's limits nearest ``qnear``
        (default all zeros), which also gives the value of a joint the pose leaves free."""
        seed = _ZERO_SEED if qnear is None else qnear
        target = self._flange_target(pose, tcp)
        found: list[IkSolution] = []
        for branch, q0 in self._closed_form.branches(target, seed):
            q = run_steps(self._solve_branch(target, q0, seed, max_position_error, max_orientation_error))
            if q is not None:
                found.append(IkSolution(branch, q))
        return found

    def nearest(
        self,
        pose: Vector,
        qnear: Vector,
        tcp: Vector | None = None,
        max_position_error: float = 1e-10,
        max_orientation_error: float = 1e-10,
    ) -> Joints | None:
        """The solution nearest ``qnear`` (Euclidean in joint space), or None if the pose has none.

        URScript ``get_inverse_kin(x, qnear, maxPositionError, maxOrientationError, tcp)``."""
        return run_steps(self.nearest_steps(pose, qnear, tcp, max_position_error, max_orientation_error))

    def nearest_steps(
        self,
        pose: Vector,
        qnear: Vector,
        tcp: Vector | None = None,
        max_position_error: float = 1e-10,
        max_orientation_error: float = 1e-10,
    ) -> Steps[Joints | None]:
        """``nearest`` in chunks (one Newton evaluation each, ~10-30 µs); returns what it returns."""
        target = self._flange_target(pose, tcp)
        ranked = sorted(
            (_distance(_shift_near(q0, qnear), qnear), branch, q0)
            for branch, q0 in self._closed_form.branches(target, qnear)
        )
        yield
        best: Joints | None = None
        best_distance = math.inf
        for nominal_distance, _, q0 in ranked:
            if nominal_distance > best_distance + _NEARER_MARGIN:
                break
            # qnear this close to the branch is the better start (a servo target, a small step).
            warm = self._calibrated and nominal_distance < _WARM_START
            start = [float(v) for v in qnear] if warm else None
            q = yield from self._solve_branch(
                target, q0, qnear, max_position_error, max_orientation_error, start
            )
            if q is not None:
                distance = _distance(q, qnear)
                if distance < best_distance:
                    best, best_distance = q, distance
        return best

    def nearest_in(
        self,
        pose: Vector,
        qnear: Vector,
        tcp: Vector | None = None,
        wanted: dict[str, str] | None = None,
        max_position_error: float = 1e-10,
        max_orientation_error: float = 1e-10,
    ) -> Joints | None:
        """The solution nearest ``qnear`` whose configuration matches every key of ``wanted``, or None.

        ``wanted`` maps any of "shoulder", "elbow", "wrist" to a value of ``Configuration``; an
        empty or missing one is ``nearest``."""
        return run_steps(
            self.nearest_in_steps(pose, qnear, tcp, wanted, max_position_error, max_orientation_error)
        )

    def nearest_in_steps(
        self,
        pose: Vector,
        qnear: Vector,
        tcp: Vector | None = None,
        wanted: dict[str, str] | None = None,
        max_position_error: float = 1e-10,
        max_orientation_error: float = 1e-10,
    ) -> Steps[Joints | None]:
        """``nearest_in`` in bounded chunks, as ``nearest_steps``."""
        if not wanted:
            return (
                yield from self.nearest_steps(pose, qnear, tcp, max_position_error, max_orientation_error)
            )
        target = self._flange_target(pose, tcp)
        best: Joints | None = None
        best_distance = math.inf
        branches = self._closed_form.branches(target, qnear)
        yield
        for _, q0 in branches:
            if not self._matches(q0, wanted):
                continue
            q = yield from self._solve_branch(target, q0, qnear, max_position_error, max_orientation_error)
            if q is not None and self._matches(q, wanted) and _distance(q, qnear) < best_distance:
                best, best_distance = q, _distance(q, qnear)
        return best

    def configuration_of(self, q: Vector) -> Configuration:
        """The named configuration of ``q`` on this arm (its nominal a2, a3, d5)."""
        return named_configuration(q, self._a2, self._a3, self._d5)

    def singularity_name(self, q: Vector) -> str:
        """Which singularity ``q`` is nearest: "wrist", "elbow" or "shoulder" (on this arm's proportions)."""
        return nearest_singularity(q, self._a2, self._a3, self._d5)

    def _matches(self, q: Vector, wanted: dict[str, str]) -> bool:
        configuration = self.configuration_of(q)._asdict()
        return all(configuration.get(key) == value for key, value in wanted.items())

    def has_solution(
        self,
        pose: Vector,
        qnear: Vector | None = None,
        tcp: Vector | None = None,
        max_position_error: float = 1e-10,
        max_orientation_error: float = 1e-10,
    ) -> bool:
        """Whether ``nearest`` finds a solution (URScript ``get_inverse_kin_has_solution``)."""
        seed = _ZERO_SEED if qnear is None else qnear
        return self.nearest(pose, seed, tcp, max_position_error, max_orientation_error) is not None

    def jacobian(self, q: Vector, tcp: Vector | None = None) -> NDArray[np.float64]:
        """The 6x6 geometric Jacobian at ``q``: rows vx vy vz wx wy wz of the TCP in base, columns joints."""
        import numpy as np

        chain = self._chain(q, None if tcp is None else frame_of_pose(tcp))
        return np.array(_jacobian_rows(chain))

    def jacobian_rows(self, q: Vector, tcp: Vector | None = None) -> list[list[float]]:
        """The geometric Jacobian at ``q`` as 6 rows (vx vy vz wx wy wz of the TCP in base) of 6 floats."""
        return _jacobian_rows(self._chain(q, None if tcp is None else frame_of_pose(tcp)))

    def joint_velocity(
        self,
        q: Vector,
        twist: Vector,
        tcp: Vector | None = None,
        *,
        singular_value: float = 0.05,
        max_damping: float = 0.05,
    ) -> Joints:
        """Joint velocities that give the TCP ``twist`` at ``q``, damped near singularities.

        Damped least squares: qd = sum sigma_i / (sigma_i^2 + l^2) v_i u_i^T twist over the singular
        values of the Jacobian, with l^2 = (1 - (sigma_min / singular_value)^2) * max_damping^2 when
        sigma_min < singular_value, else 0 (the exact inverse away from singularities)."""
        import numpy as np

        jac = self.jacobian(q, tcp)
        u, sigma, vt = np.linalg.svd(jac)
        smallest = float(sigma[5])
        damping = 0.0
        if smallest < singular_value:
            damping = (1.0 - (smallest / singular_value) ** 2) * max_damping * max_damping
        gain = sigma / (sigma * sigma + damping) if damping > 0.0 else 1.0 / sigma
        qd = vt.T @ (gain * (u.T @ np.asarray(twist, dtype=np.float64)))
        return (float(qd[0]), float(qd[1]), float(qd[2]), float(qd[3]), float(qd[4]), float(qd[5]))

    # ---- stages --------------------------------------------------------------------------------

    def _flange_target(self, pose: Vector, tcp: Vector | None) -> Frame:
        target = frame_of_pose(pose)
        return target if tcp is None else compose(target, inverse(frame_of_pose(tcp)))

    def _solve_branch(
        self,
        target: Frame,
        q0: list[float],
        seed: Vector,
        max_position: float,
        max_orientation: float,
        start: list[float] | None = None,
    ) -> Steps[Joints | None]:
        """Refine a nominal branch on the calibrated arm (from ``start`` if given); check errors, limits."""
        q, position_error, orientation_error = yield from self._refine(target, q0 if start is None else start)
        if start is not None and not (
            position_error <= max_position and orientation_error <= max_orientation
        ):
            q, position_error, orientation_error = yield from self._refine(target, q0)
        if self._calibrated and not (position_error <= max_position and orientation_error <= max_orientation):
            q, position_error, orientation_error = yield from self._continuation(target, q0)
            if not (position_error <= max_position and orientation_error <= max_orientation):
                return None
        return self._within_limits(_shift_near(q, seed))

    def _continuation(self, target: Frame, q: list[float]) -> Steps[tuple[list[float], float, float]]:
        """Follow the branch from where ``q`` puts the calibrated arm to ``target`` in small steps.

        The fallback when Newton's steps from the nominal branch do not converge: near a singularity
        the calibrated branch can lie far (in joints) from the nominal one. A waypoint the branch does
        not reach ends the attempt (so an unreachable pose costs a few steps per branch)."""
        start = self._chain(q, None).frame
        yield
        sx, sy, sz = start[9], start[10], start[11]
        dx, dy, dz = target[9] - sx, target[10] - sy, target[11] - sz
        # The rotation from the start's orientation to the target's, in base, as a rotation vector.
        rx, ry, rz = rotation_vector(*compose(target, inverse(start))[:9])
        rotation: Frame = (*start[:9], 0.0, 0.0, 0.0)
        for k in range(1, _CONTINUATION_STEPS):
            s = k / _CONTINUATION_STEPS
            turned = compose(frame_of_pose((0.0, 0.0, 0.0, s * rx, s * ry, s * rz)), rotation)
            waypoint: Frame = (*turned[:9], sx + s * dx, sy + s * dy, sz + s * dz)
            q, position, orientation = yield from self._refine(waypoint, q)
            if position + orientation > _WAYPOINT_TOLERANCE:
                return q, math.inf, math.inf  # the branch does not reach this far: give up early
        return (yield from self._refine(target, q))

    def _refine(self, target: Frame, q: list[float]) -> Steps[tuple[list[float], float, float]]:
        """Levenberg-Marquardt steps on the calibrated arm from ``q`` (a nominal branch).

        The damping starts at the squared error (so Newton's quadratic convergence near the solution)
        and grows tenfold after a step that does not lower the error. Returns the joints and their
        position and orientation errors (m, rad). Yields after each evaluation but the first (a chunk:
        one damped step and one evaluation of the chain)."""
        chain, error, position, orientation = self._error(target, q)
        yield
        evaluations = 1
        slow = 0
        while evaluations < _NEWTON_EVALUATIONS:
            total = position + orientation
            if position < _NEWTON_TOLERANCE and orientation < _NEWTON_TOLERANCE:
                break
            rows = _jacobian_rows(chain)
            damping = total * total + 1e-24
            while evaluations < _NEWTON_EVALUATIONS and damping < 1.0:
                step = damped_step6(rows, error, damping)
                trial = [q[i] + step[i] for i in range(6)]
                evaluations += 1
                trial_chain, trial_error, trial_position, trial_orientation = self._error(target, trial)
                yield
                if trial_position + trial_orientation < total:
                    q, chain, error = trial, trial_chain, trial_error
                    position, orientation = trial_position, trial_orientation
                    break
                damping *= 10.0
            else:
                break  # no step lowers the error: at the rounding floor, or stuck
            if position + orientation > 0.5 * total:
                slow += 1
                if slow >= _SLOW_STEPS:
                    break  # creeping towards the nearest pose the arm can reach: not a solution
        return q, position, orientation

    def _error(self, target: Frame, q: list[float]) -> tuple[_Chain, tuple[float, ...], float, float]:
        """The chain at ``q`` and the twist from it to ``target`` (position, rotation vector in base)."""
        chain = self._chain(q, None)
        return (chain, *twist_error(target, chain.frame))

    # ---- the calibrated chain ------------------------------------------------------------------

    def _frame(self, q: Vector) -> Frame:
        return self._chain(q, None).frame

    def _chain(self, q: Vector, tcp: Frame | None) -> _Chain:
        axes: list[tuple[float, float, float]] = []
        points: list[tuple[float, float, float]] = []
        frame: Frame = dh_chain(self._joints, q, axes, points)
        if tcp is not None:
            frame = compose(frame, tcp)
        return _Chain(frame, tuple(axes), tuple(points))

    def _within_limits(self, q: Joints) -> Joints | None:
        """``q`` (shifted near the seed), each joint turned by whole turns just into its limits; or None."""
        return _within(q, self._lower, self._upper)


def _jacobian_rows(chain: _Chain) -> list[list[float]]:
    """Rows of the geometric Jacobian: column i is (z_i x (p - o_i), z_i)."""
    f = chain.frame
    px, py, pz = f[9], f[10], f[11]
    rows: list[list[float]] = [[], [], [], [], [], []]
    for (zx, zy, zz), (ox, oy, oz) in zip(chain.axes, chain.points, strict=True):
        dx, dy, dz = px - ox, py - oy, pz - oz
        rows[0].append(zy * dz - zz * dy)
        rows[1].append(zz * dx - zx * dz)
        rows[2].append(zx * dy - zy * dx)
        rows[3].append(zx)
        rows[4].append(zy)
        rows[5].append(zz)
    return rows


def _shift_near(q: Vector, seed: Vector) -> Joints:
    """Each joint shifted by a multiple of 2pi to lie nearest the seed's."""
    out = [v + _TAU * round((s - v) / _TAU) for v, s in zip(q, seed, strict=True)]
    return (out[0], out[1], out[2], out[3], out[4], out[5])


def _distance(q: Vector, seed: Vector) -> float:
    return math.sqrt(sum((a - b) * (a - b) for a, b in zip(q, seed, strict=True)))


def _within(q: Joints, lowers: Sequence[float], uppers: Sequence[float]) -> Joints | None:
    """``q``, each joint turned by whole turns just into [lower, upper]; None if one cannot be."""
    out = list(q)
    for i, (lower, upper) in enumerate(zip(lowers, uppers, strict=True)):
        value = out[i]
        if value > upper:
            value -= _TAU * math.ceil((value - upper) / _TAU)
        elif value < lower:
            value += _TAU * math.ceil((lower - value) / _TAU)
        if not lower <= value <= upper:
            return None
        out[i] = value
    return (out[0], out[1], out[2], out[3], out[4], out[5])


def twist_error(target: Frame, frame: Frame) -> tuple[tuple[float, ...], float, float]:
    """The twist from ``frame`` to ``target`` (position difference, rotation vector in base) and its
    sizes (m, rad): the error Newton's steps drive to zero (here and in chain.py)."""
    t, r = target, frame
    ex, ey, ez = t[9] - r[9], t[10] - r[10], t[11] - r[11]
    # target * frame^T: the rotation taking the current tool to the target, in base.
    wx, wy, wz = rotation_vector(
        t[0] * r[0] + t[1] * r[1] + t[2] * r[2],
        t[0] * r[3] + t[1] * r[4] + t[2] * r[5],
        t[0] * r[6] + t[1] * r[7] + t[2] * r[8],
        t[3] * r[0] + t[4] * r[1] + t[5] * r[2],
        t[3] * r[3] + t[4] * r[4] + t[5] * r[5],
        t[3] * r[6] + t[4] * r[7] + t[5] * r[8],
        t[6] * r[0] + t[7] * r[1] + t[8] * r[2],
        t[6] * r[3] + t[7] * r[4] + t[8] * r[5],
        t[6] * r[6] + t[7] * r[7] + t[8] * r[8],
    )
    position = math.sqrt(ex * ex + ey * ey + ez * ez)
    orientation = math.sqrt(wx * wx + wy * wy + wz * wz)
    return (ex, ey, ez, wx, wy, wz), position, orientation
