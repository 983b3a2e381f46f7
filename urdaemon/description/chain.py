"""Numeric kinematics of a serial chain read from a URDF: custom robots' ``ArmKinematics``.

``ChainKinematics(tree, base, tool, joint_names)`` walks the ``KinematicTree`` joints from link
``base`` to link ``tool`` (revolute, continuous, prismatic, fixed; mimic joints follow their source)
and solves poses by damped Newton steps (Levenberg-Marquardt) from ``qnear``, inside the joint
limits, with a few restarts from fixed seeds when that does not converge. No branches: the solution
is the one Newton's steps reach from ``qnear`` (or from the restart nearest it). Plain floats, no
numpy (it runs in the serve process). Conventions as ik.py's: poses (x, y, z, rx, ry, rz) of the TCP
in the ``base`` link's frame, ``tcp`` the tool link -> TCP pose, q in ``joint_names`` order.

``nearest_steps`` is ``nearest`` in bounded chunks (a generator yielding after each Newton
evaluation: one damped step and one walk of the chain with its Jacobian, ~20-60 µs); ``nearest``
runs it to the end. An unreachable pose costs up to nine starts of up to 60 evaluations (2-4 ms):
the event loop takes it a chunk at a time between robot cycles.
"""

from __future__ import annotations

import math
from collections.abc import Generator, Sequence
from operator import mul
from typing import NamedTuple

from urdaemon.description.dls import cholesky_solve, damped_step6, gram
from urdaemon.description.frames import (
    IDENTITY,
    Frame,
    Pose,
    axis_rotation,
    compose,
    frame_of_pose,
    inverse,
    pose_of_frame,
)
from urdaemon.description.ik import twist_error as _error
from urdaemon.description.ik_types import run_steps
from urdaemon.description.kinematics import KinematicTree, TreeJoint
from urdaemon.errors import DescriptionError

__all__ = ["ChainKinematics"]

_EVALUATIONS = 60
"""Newton evaluations per start before it gives up."""
_STALL_WINDOW = 10
"""Newton gives up when the error has not halved over this many evaluations (no solution near)."""
_RESTARTS = 8
"""Fixed seeds tried after ``qnear`` (a deterministic spread over the joint ranges)."""
_TOLERANCE = 1e-12
"""Newton stops below this (m and rad), well under the default acceptance of 1e-10."""
_MAX_STEP = 0.5
"""Largest joint step (rad or m, infinity norm) of one Newton step: keeps it in qnear's basin."""
_SPAN = math.pi
"""Half-width of the seed range for a joint without limits (continuous)."""
_TAU = 2.0 * math.pi


class _Step(NamedTuple):
    """One joint of the chain: its origin, and for a moving one its axis, column, multiplier, offset."""

    origin: Frame
    kind: str  # "fixed" | "revolute" | "prismatic"
    axis: tuple[float, float, float]
    column: int
    multiplier: float
    offset: float


class ChainKinematics:
    """Forward and inverse kinematics and the Jacobian of the URDF chain ``base`` -> ``tool``.

    ``bounds`` (lower, upper per joint of ``joint_names``) bound the answers; without it a revolute
    joint is unbounded (continuous) and a prismatic one too. A joint of ``joint_names`` not on the
    chain gives a zero Jacobian column and keeps ``qnear``'s value."""

    __slots__ = ("_base", "_lower", "_moving", "_revolute", "_steps", "_upper", "dof")

    branches: bool = False
    """No named configurations: the solution is the one reached from ``qnear``."""

    def __init__(
        self,
        tree: KinematicTree,
        base: str,
        tool: str,
        joint_names: Sequence[str],
        bounds: tuple[Sequence[float], Sequence[float]] | None = None,
    ) -> None:
        self.dof: int = len(joint_names)
        columns = {name: i for i, name in enumerate(joint_names)}
        up, down = _path(tree, base, tool)
        fixed_up = IDENTITY
        for joint in reversed(up):
            if joint.type != "fixed":
                raise DescriptionError(
                    f"chain {base!r} -> {tool!r}: joint {joint.name!r} moves {base!r} itself"
                )
            fixed_up = compose(fixed_up, joint.origin)
        self._base = inverse(fixed_up)
        self._steps = tuple(_step(joint, columns, base, tool) for joint in down)
        revolute = [False] * self.dof
        moving = [False] * self.dof
        for step in self._steps:
            if step.kind != "fixed":
                moving[step.column] = True
                revolute[step.column] = step.kind == "revolute"
        self._revolute, self._moving = tuple(revolute), tuple(moving)
        lower = [-math.inf] * self.dof if bounds is None else [float(v) for v in bounds[0]]
        upper = [math.inf] * self.dof if bounds is None else [float(v) for v in bounds[1]]
        if len(lower) != self.dof or len(upper) != self.dof:
            raise DescriptionError(
                f"chain {base!r} -> {tool!r}: bounds for {len(lower)} joints, not {self.dof}"
            )
        self._lower, self._upper = tuple(lower), tuple(upper)

    # ---- ArmKinematics -------------------------------------------------------------------------

    def forward(self, q: Sequence[float], tcp: Sequence[float] | None = None) -> Pose:
        """The TCP pose (in the base link's frame) for joints ``q``."""
        frame = self._walk(q, None)
        if tcp is not None:
            frame = compose(frame, frame_of_pose(tcp))
        return pose_of_frame(frame)

    def jacobian_rows(self, q: Sequence[float], tcp: Sequence[float] | None = None) -> list[list[float]]:
        """6 rows (vx vy vz wx wy wz of the TCP, base frame) x dof columns."""
        rows: list[list[float]] = [[0.0] * self.dof for _ in range(6)]
        frame = self._walk(q, rows)
        if tcp is not None:
            _move_point(rows, frame, compose(frame, frame_of_pose(tcp)))
        return rows

    def nearest(
        self,
        pose: Sequence[float],
        qnear: Sequence[float],
        tcp: Sequence[float] | None = None,
        max_position_error: float = 1e-10,
        max_orientation_error: float = 1e-10,
    ) -> tuple[float, ...] | None:
        """The joints reaching ``pose`` that Newton's steps find from ``qnear``, within the limits; or None.

        When the steps from ``qnear`` do not converge to the tolerances, each fixed seed is tried and
        the converged solution nearest ``qnear`` wins. None when none converges (out of reach, or
        off the manifold of an arm with fewer than six joints)."""
        return run_steps(self.nearest_steps(pose, qnear, tcp, max_position_error, max_orientation_error))

    def nearest_steps(
        self,
        pose: Sequence[float],
        qnear: Sequence[float],
        tcp: Sequence[float] | None = None,
        max_position_error: float = 1e-10,
        max_orientation_error: float = 1e-10,
    ) -> Generator[None, None, tuple[float, ...] | None]:
        """``nearest`` in bounded chunks: yields after each Newton evaluation; returns what ``nearest``
        returns."""
        target = frame_of_pose(pose)
        if tcp is not None:
            target = compose(target, inverse(frame_of_pose(tcp)))
        near = [float(v) for v in qnear]
        found = yield from self._converge(
            target, self._clamped(near), max_position_error, max_orientation_error
        )
        if found is not None:
            return tuple(self._wrapped(found, near))
        best: list[float] | None = None
        best_distance = math.inf
        for seed in self._seeds(near):
            q = yield from self._converge(target, seed, max_position_error, max_orientation_error)
            if q is not None:
                q = self._wrapped(q, near)
                distance = math.dist(q, near)
                if distance < best_distance:
                    best, best_distance = q, distance
        return None if best is None else tuple(best)

    # ---- Newton --------------------------------------------------------------------------------

    def _converge(
        self, target: Frame, q: list[float], max_position: float, max_orientation: float
    ) -> Generator[None, None, list[float] | None]:
        """Levenberg-Marquardt from ``q`` inside the limits; the joints if within the tolerances.
        Yields after each evaluation of the chain."""
        rows: list[list[float]] = [[0.0] * self.dof for _ in range(6)]
        error, position, orientation = _error(target, self._walk(q, rows))
        yield
        damping = 1e-3
        checkpoint = math.inf
        for evaluation in range(_EVALUATIONS):
            if position < _TOLERANCE and orientation < _TOLERANCE:
                break
            total = position + orientation
            if evaluation % _STALL_WINDOW == 0:
                if total > 0.5 * checkpoint:
                    break  # not halving the error any more: stuck at the nearest reachable pose
                checkpoint = total
            step = self._step(rows, error, damping * total * total + 1e-24)
            trial = self._clamped([a + b for a, b in zip(q, step, strict=True)])
            trial_rows: list[list[float]] = [[0.0] * self.dof for _ in range(6)]
            trial_error, trial_position, trial_orientation = _error(target, self._walk(trial, trial_rows))
            yield
            if trial_position + trial_orientation < total:
                q, rows, error = trial, trial_rows, trial_error
                position, orientation = trial_position, trial_orientation
                damping = max(damping * 0.1, 1e-3)
            else:
                damping *= 10.0
                if damping > 1e12:
                    break  # no step lowers the error: a local minimum off the target
        if position <= max_position and orientation <= max_orientation:
            return q
        return None

    def _step(self, rows: list[list[float]], error: Sequence[float], damping: float) -> list[float]:
        """The damped least-squares step J^T (J J^T + d)^-1 e (or its n < 6 form), at most _MAX_STEP."""
        try:
            if self.dof == 6:
                step = damped_step6(rows, error, damping)
            elif self.dof < 6:
                jt_e = [sum(rows[k][j] * error[k] for k in range(6)) for j in range(self.dof)]
                step = cholesky_solve(gram(rows), jt_e, damping)
            else:
                y = cholesky_solve(gram(rows), error, damping)
                step = [sum(map(mul, column, y)) for column in zip(*rows, strict=True)]
        except ZeroDivisionError:  # damping too small for a rank-deficient Jacobian
            return [0.0] * self.dof
        largest = max((abs(v) for v in step), default=0.0)
        if largest > _MAX_STEP:
            step = [v * (_MAX_STEP / largest) for v in step]
        return step

    def _seeds(self, near: Sequence[float]) -> list[list[float]]:
        """Fixed restart seeds: the middle of the ranges, then points spread by a Halton sequence."""
        seeds: list[list[float]] = []
        for k in range(_RESTARTS):
            seed = []
            for i in range(self.dof):
                lower, upper = self._lower[i], self._upper[i]
                if not (math.isfinite(lower) and math.isfinite(upper)):
                    lower, upper = near[i] - _SPAN, near[i] + _SPAN
                fraction = 0.5 if k == 0 else _halton(k, _PRIMES[i % len(_PRIMES)])
                seed.append(lower + fraction * (upper - lower))
            seeds.append(seed)
        return seeds

    def _clamped(self, q: list[float]) -> list[float]:
        return [min(hi, max(lo, v)) for v, lo, hi in zip(q, self._lower, self._upper, strict=True)]

    def _wrapped(self, q: list[float], near: Sequence[float]) -> list[float]:
        """Each revolute joint turned by whole turns nearest ``near`` while inside its limits; a joint
        off the chain at ``near``'s value (a restart's seed moved it)."""
        out = list(q)
        for i, revolute in enumerate(self._revolute):
            if not self._moving[i]:
                out[i] = min(self._upper[i], max(self._lower[i], float(near[i])))
            if not revolute:
                continue
            shifted = out[i] + _TAU * round((near[i] - out[i]) / _TAU)
            if self._lower[i] <= shifted <= self._upper[i]:
                out[i] = shifted
        return out

    # ---- the chain -----------------------------------------------------------------------------

    def _walk(self, q: Sequence[float], rows: list[list[float]] | None) -> Frame:
        """The tool frame in base for ``q``; with ``rows``, the Jacobian columns are added into them."""
        frame = self._base
        axes: list[tuple[int, float, str, float, float, float, float, float, float]] = []
        for step in self._steps:
            frame = compose(frame, step.origin)
            if step.kind == "fixed":
                continue
            value = step.multiplier * q[step.column] + step.offset
            ax, ay, az = step.axis
            r = frame
            wx = r[0] * ax + r[1] * ay + r[2] * az
            wy = r[3] * ax + r[4] * ay + r[5] * az
            wz = r[6] * ax + r[7] * ay + r[8] * az
            if rows is not None:
                axes.append((step.column, step.multiplier, step.kind, wx, wy, wz, r[9], r[10], r[11]))
            if step.kind == "revolute":
                frame = compose(frame, axis_rotation(ax, ay, az, value))
            else:
                frame = (*frame[:9], frame[9] + wx * value, frame[10] + wy * value, frame[11] + wz * value)
        if rows is not None:
            px, py, pz = frame[9], frame[10], frame[11]
            for column, k, kind, zx, zy, zz, ox, oy, oz in axes:
                if kind == "revolute":
                    dx, dy, dz = px - ox, py - oy, pz - oz
                    rows[0][column] += k * (zy * dz - zz * dy)
                    rows[1][column] += k * (zz * dx - zx * dz)
                    rows[2][column] += k * (zx * dy - zy * dx)
                    rows[3][column] += k * zx
                    rows[4][column] += k * zy
                    rows[5][column] += k * zz
                else:
                    rows[0][column] += k * zx
                    rows[1][column] += k * zy
                    rows[2][column] += k * zz
        return frame


_PRIMES = (2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37)


def _halton(index: int, base: int) -> float:
    """The ``index``-th point of the van der Corput sequence in ``base`` (in (0, 1))."""
    result, fraction = 0.0, 1.0
    while index > 0:
        fraction /= base
        result += fraction * (index % base)
        index //= base
    return result


def _move_point(rows: list[list[float]], flange: Frame, tcp: Frame) -> None:
    """Re-express the linear rows for the TCP point: v_tcp = v_flange + w x (p_tcp - p_flange)."""
    dx, dy, dz = tcp[9] - flange[9], tcp[10] - flange[10], tcp[11] - flange[11]
    for j in range(len(rows[0])):
        wx, wy, wz = rows[3][j], rows[4][j], rows[5][j]
        rows[0][j] += wy * dz - wz * dy
        rows[1][j] += wz * dx - wx * dz
        rows[2][j] += wx * dy - wy * dx


def _path(tree: KinematicTree, base: str, tool: str) -> tuple[list[TreeJoint], list[TreeJoint]]:
    """Joints from ``base`` up to the common ancestor (base first), and from it down to ``tool``."""
    by_child = {joint.child: joint for joint in tree.joints}
    for link in (base, tool):
        if link != tree.root and link not in by_child:
            raise DescriptionError(f"the URDF has no link {link!r}")

    def ancestry(link: str) -> list[TreeJoint]:
        joints = []
        while link in by_child:
            joints.append(by_child[link])
            link = by_child[link].parent
        return joints

    up, down = ancestry(base), ancestry(tool)
    # Drop the shared part above the common ancestor.
    while up and down and up[-1] is down[-1]:
        up.pop()
        down.pop()
    return up, down[::-1]


def _step(joint: TreeJoint, columns: dict[str, int], base: str, tool: str) -> _Step:
    if joint.type == "fixed":
        return _Step(joint.origin, "fixed", (0.0, 0.0, 1.0), 0, 0.0, 0.0)
    if joint.type not in ("revolute", "continuous", "prismatic"):
        raise DescriptionError(
            f"chain {base!r} -> {tool!r}: joint {joint.name!r} is {joint.type!r}; "
            "a chain takes revolute, continuous, prismatic and fixed joints"
        )
    kind = "prismatic" if joint.type == "prismatic" else "revolute"
    source, multiplier, offset = joint.name, 1.0, 0.0
    if joint.mimic is not None:
        source, multiplier, offset = joint.mimic
    if source not in columns:
        raise DescriptionError(
            f"chain {base!r} -> {tool!r}: joint {joint.name!r} moves but is not one of the robot's joints"
        )
    return _Step(joint.origin, kind, joint.axis, columns[source], multiplier, offset)
