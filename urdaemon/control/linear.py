"""Linear goals: a straight TCP path through poses, checked completely and sampled every cycle.

``plan_linear`` plans in small steps, a generator whose return value is the plan (no clock inside:
the runtime runs it in slices between the robot's cycles, like control/trajectory.py's
``check_points``):

1. the arguments, then each pose's reach (``kin.nearest_steps`` seeded with the pose before it): a pose
   out of reach is refused before anything is sampled;
2. the path (control/cartesian.py ``LinePath``): straight lines timed by jerk-limited profiles within
   the Cartesian limits, blended where asked;
3. the samples, one in two steps: at every ``period`` (the robot's cycle) the path's pose is converted to
   joints by ``kin.nearest_steps`` seeded with the sample before (IK continuity). The first sample is
   ``start`` exactly, the last the IK of the last pose. Each sample is refused (GoalRejected, naming the
   segment, how far along it and the TCP position) when its IK fails, a joint leaves ``limits``, the
   arm comes within ``SINGULARITY_LIMIT`` of a singularity, or the arm flips branch (a joint step far
   larger than the Cartesian step explains, or a UR configuration change);
4. the finite differences of the samples (joint velocity, acceleration and jerk against ``limits``;
   the TCP's speed, acceleration and jerk and its angular ones against the Cartesian limits, which a
   blend's two superposed motions may exceed): if any is exceeded, the whole path is retimed uniformly
   by the smallest factor ``k`` that fits them all (speed / k, acceleration / k^2, jerk / k^3) and
   sampled again. A linear goal near a singularity or a joint's speed limit so runs slower than asked:
   the plan says by how much (``SampledTrajectory.slowed_by``); more than ``MAX_SLOWDOWN`` is refused.

Every IK runs through ``kin.nearest_steps``, whose chunks (one Newton evaluation each) are steps of
the check: however far out of reach a pose is (a custom robot's numeric IK then tries nine starts),
no step holds the event loop for more than one evaluation.

Segment ``k`` is the line that ends at pose ``k`` (0-based, as the goal lists them); positions in
reasons are the TCP's in the robot's base frame.
"""

from __future__ import annotations

import math
from collections.abc import Generator, Sequence

from urdaemon.control.cartesian import CartesianLimits, LinePath, build_path
from urdaemon.control.sampled import SampledTrajectory, SampleWriter
from urdaemon.description.arm import ArmKinematics
from urdaemon.description.dls import singularity
from urdaemon.description.frames import (
    Frame,
    Pose,
    compose,
    frame_of_pose,
    inverse,
    pose_of_frame,
    rotation_vector,
)
from urdaemon.errors import GoalRejected
from urdaemon.model import JointLimits

__all__ = [
    "FLIP_RATIO",
    "JOINT_NOISE",
    "LIMIT_TOLERANCE",
    "MAX_LINEAR_TIME_S",
    "MAX_POSES",
    "MAX_SLOWDOWN",
    "SINGULARITY_LIMIT",
    "plan_linear",
]

SINGULARITY_LIMIT = 0.02
"""Smallest singular value of the TCP Jacobian (rows m/s and rad/s, base frame) a path may come to.
On a UR5e with no TCP offset this is wrist_2 within ~3.5 deg of 0 or the elbow within ~7 deg of straight;
nearer, joint speeds grow as 1/sigma and the branch is ill-defined."""
FLIP_RATIO = 4.0
"""A joint step (2-norm, rad) more than this times |Cartesian step| / sigma_min is a branch flip: a
continuous solution moves at most |step| / sigma_min (to first order)."""
MAX_SLOWDOWN = 10.0
"""Most a linear goal is slowed to keep the joint (or, in a blend, the Cartesian) limits; beyond it the
goal is refused, naming where the limit is hit."""
MAX_LINEAR_TIME_S = 600.0
"""Longest linear goal (s): its samples take ~48 KB per second of motion at 500 Hz."""
MAX_POSES = 1000
"""Most poses in one linear goal."""
LIMIT_TOLERANCE = 1e-6
"""Relative slack of every finite-difference check (float rounding)."""
JOINT_NOISE = 1e-10
"""rad: the IK's accuracy. A finite difference of order m over samples h apart may carry
2^m * JOINT_NOISE / h^m of it, which the joint checks allow on top of the limit."""
_POSE_NOISE = 1e-12
"""m and rad: the same for the path's own poses (float rounding)."""
_MAX_PASSES = 4
_RETIME_MARGIN = 1e-3
"""A retimed path is slowed this much more than the differences asked, so one pass usually fits."""


def plan_linear(
    kin: ArmKinematics,
    start: Sequence[float],
    poses: Sequence[Sequence[float]],
    blends: Sequence[float],
    tcp: Sequence[float],
    cartesian: CartesianLimits,
    limits: JointLimits,
    period: float,
) -> Generator[None, None, SampledTrajectory]:
    """Plan a linear goal from joints ``start`` (at rest) through ``poses`` (TCP poses in base, with
    the flange -> TCP pose ``tcp``), blend radius ``blends[k]`` (m) at pose ``k`` (empty: none),
    sampled every ``period`` s, in steps: a generator whose return value is the sampled plan. Pure: no
    clock inside; a step is one chunk of an IK (one Newton evaluation), a segment's profile or a
    sample's checks (its Jacobian, a bound of its smallest singular value, its finite differences):
    each some 10-60 µs. Every refusal is raised by a step as GoalRejected."""
    return _plan(kin, start, poses, blends, tcp, cartesian, limits, period)


def _plan(
    kin: ArmKinematics,
    start: Sequence[float],
    poses: Sequence[Sequence[float]],
    blends: Sequence[float],
    tcp: Sequence[float],
    cartesian: CartesianLimits,
    limits: JointLimits,
    period: float,
) -> Generator[None, None, SampledTrajectory]:
    goal = _checked_arguments(kin, start, poses, blends, tcp, limits, period)
    q0 = tuple(float(v) for v in start)
    seed: Sequence[float] = q0
    for k, pose in enumerate(goal):
        q = yield from kin.nearest_steps(pose, seed, tcp)
        if q is None:
            raise GoalRejected(f"linear goal: pose {k} is out of reach (no joint solution within the limits)")
        seed = q
        yield
    radii = list(blends) if blends else [0.0] * (len(goal) - 1)
    path = yield from build_path(kin.forward(q0, tcp), goal, radii, cartesian)
    if path.duration > MAX_LINEAR_TIME_S:
        raise GoalRejected(
            f"linear goal: it would take {path.duration:.6g} s, longer than the longest linear goal, "
            f"{MAX_LINEAR_TIME_S:.6g} s"
        )
    wanted = 1.0  # the slowdown asked for; the grid rounds the duration up to a whole cycle on top
    slow = _grid_factor(path.duration, period, wanted)
    for _ in range(_MAX_PASSES):
        sampler = _Sampler(kin, path, q0, tcp, cartesian, limits, period, slow)
        yield from sampler.run()
        need = sampler.worst.need
        if need <= 1.0:
            return sampler.writer.finish(wanted)
        if slow * need > MAX_SLOWDOWN or path.duration * slow * need > MAX_LINEAR_TIME_S:
            raise GoalRejected(sampler.worst.reason(path, slow * need))
        wanted = slow * need * (1.0 + _RETIME_MARGIN)
        slow = _grid_factor(path.duration, period, wanted)
    raise GoalRejected(sampler.worst.reason(path, slow))


def _grid_factor(duration: float, period: float, wanted: float) -> float:
    """The factor >= ``wanted`` that makes the retimed duration a whole number of periods."""
    if duration <= 0.0:
        return 1.0
    cycles = math.ceil(duration * wanted / period - 1e-9)
    return max(cycles, 1) * period / duration


def _finite(values: Sequence[float]) -> bool:
    return all(isinstance(v, (int, float)) and math.isfinite(v) for v in values)


def _checked_arguments(
    kin: ArmKinematics,
    start: Sequence[float],
    poses: Sequence[Sequence[float]],
    blends: Sequence[float],
    tcp: Sequence[float],
    limits: JointLimits,
    period: float,
) -> list[Pose]:
    """The poses as tuples, after checking every argument (GoalRejected names the fault)."""
    n = limits.dof
    if kin.dof != n or len(start) != n:
        raise GoalRejected(
            f"linear goal: the start has {len(start)} joints, the arm {kin.dof}, the limits {n}"
        )
    if not _finite(start):
        raise GoalRejected("linear goal: the start joints must be finite numbers")
    if not 1 <= len(poses) <= MAX_POSES:
        raise GoalRejected(f"linear goal: poses must hold 1 to {MAX_POSES} poses, got {len(poses)}")
    goal: list[Pose] = []
    for k, pose in enumerate(poses):
        if len(pose) != 6 or not _finite(pose):
            raise GoalRejected(f"linear goal: pose {k} must be 6 finite numbers (x, y, z, rx, ry, rz)")
        goal.append(
            (float(pose[0]), float(pose[1]), float(pose[2]), float(pose[3]), float(pose[4]), float(pose[5]))
        )
    if blends and len(blends) != len(poses) - 1:
        raise GoalRejected(
            f"linear goal: blend_radii must hold one radius per pose but the last ({len(poses) - 1}), "
            f"got {len(blends)}"
        )
    for k, radius in enumerate(blends):
        if not (_finite((radius,)) and radius >= 0.0):
            raise GoalRejected(f"linear goal: blend radius {k} must be a finite number >= 0, got {radius}")
    if len(tcp) != 6 or not _finite(tcp):
        raise GoalRejected("linear goal: the tcp must be 6 finite numbers")
    if not (math.isfinite(period) and period > 0.0):
        raise GoalRejected(f"linear goal: the period must be > 0, got {period}")
    return goal


def _where(path: LinePath, tau: float, frame: Frame) -> tuple[str, str]:
    """('segment k', 'at p% (x, y, z = ... m in base)') for path time ``tau``."""
    segment, fraction = path.where(tau)
    return (
        f"segment {segment}",
        f"at {100.0 * fraction:.0f}% (x, y, z = {frame[9]:.4f}, {frame[10]:.4f}, {frame[11]:.4f} m in base)",
    )


class _Worst:
    """The largest slowdown the finite differences ask for, and what and where it is."""

    __slots__ = ("frame", "limit", "need", "tau", "value", "what")

    def __init__(self) -> None:
        self.need = 1.0
        self.what = ""
        self.value = 0.0
        self.limit = 0.0
        self.tau = 0.0
        self.frame: Frame = frame_of_pose((0.0,) * 6)

    def offer(self, need: float, what: str, value: float, limit: float, tau: float, frame: Frame) -> None:
        if need > self.need:
            self.need, self.what, self.value, self.limit, self.tau, self.frame = (
                need,
                what,
                value,
                limit,
                tau,
                frame,
            )

    def reason(self, path: LinePath, slowdown: float) -> str:
        segment, at = _where(path, self.tau, self.frame)
        return (
            f"linear goal: it would have to run {slowdown:.3g} times slower than asked (at most "
            f"{MAX_SLOWDOWN:.3g}): on {segment} {at} the {self.what} would be {self.value:.4g} against its "
            f"limit {self.limit:.4g}"
        )


_ORDERS = ("velocity", "acceleration", "jerk")


class _Sampler:
    """One pass over the path at retiming factor ``k``: samples, their checks, the writer."""

    def __init__(
        self,
        kin: ArmKinematics,
        path: LinePath,
        start: tuple[float, ...],
        tcp: Sequence[float],
        cartesian: CartesianLimits,
        limits: JointLimits,
        period: float,
        k: float,
    ) -> None:
        self.kin, self.path, self.start, self.tcp = kin, path, start, tcp
        self.limits, self.period, self.k = limits, period, k
        self.count = round(path.duration * k / period) + 1 if path.duration > 0.0 else 1
        self.writer = SampleWriter(limits.dof, period)
        self.worst = _Worst()
        h = period
        # Per order m: the joint limits and the noise 2^m * JOINT_NOISE / h^m allowed on top.
        self._joint_limits = (limits.max_velocity, limits.max_acceleration, limits.max_jerk)
        self._joint_noise = tuple((2.0**m) * JOINT_NOISE / h**m for m in (1, 2, 3))
        self._linear = (cartesian.speed, cartesian.acceleration, cartesian.jerk)
        self._angular = (cartesian.angular_speed, cartesian.angular_acceleration, cartesian.angular_jerk)
        self._pose_noise = tuple((2.0**m) * _POSE_NOISE / h**m for m in (1, 2, 3))
        self._q = [start, start, start, start]  # the last four samples, newest last (at rest before 0)
        self._x = [(0.0, 0.0, 0.0)] * 4  # the TCP positions of the same samples
        self._w = [(0.0, 0.0, 0.0)] * 3  # angular velocities of the last three intervals
        self._frame: Frame = frame_of_pose(path.start)
        self._sigma = math.inf
        self._ref_rows: list[list[float]] | None = None
        self._configuration = _configuration(kin, start)
        self._ref_sigma = 0.0

    def run(self) -> Generator[None, None, None]:
        """Sample the path, a sample in steps (its IK's chunks; its checks); then the differences into
        rest."""
        path = self.path
        last = self.count - 1
        end = frame_of_pose(path.end)
        start = frame_of_pose(path.start)
        x0 = (start[9], start[10], start[11])
        self._x = [x0, x0, x0, x0]
        for n in range(self.count):
            tau = n * self.period / self.k
            if n == 0:
                self._accept(self.start, start, tau, first=True)
            else:
                frame = end if n == last else path.frame_at(tau)
                pose = path.end if n == last else pose_of_frame(frame)
                q = yield from self.kin.nearest_steps(pose, self._q[-1], self.tcp)
                yield  # the IK's last chunk ends a step; the checks are the next
                self._check_sample(q, frame, tau)
                assert q is not None
                self._accept(q, frame, tau)
            yield
        # The robot rests at the last sample: the differences into rest count too.
        final = self._q[-1]
        for _ in range(3):
            self._differences(final, self._frame, path.duration)

    def _accept(self, q: Sequence[float], frame: Frame, tau: float, *, first: bool = False) -> None:
        q = tuple(q)
        if not first:
            self._differences(q, frame, tau)
        else:
            self._q = [q, q, q, q]
        self._frame = frame
        self.writer.append(q)

    def _check_sample(self, q: tuple[float, ...] | None, frame: Frame, tau: float) -> None:
        """Refuse a sample that fails its IK, leaves the limits, nears a singularity or flips branch."""
        prev = self._q[-1]
        if q is None:
            self._refuse_limit(self._extrapolated(), frame, tau)
            segment, at = _where(self.path, tau, frame)
            raise GoalRejected(f"linear goal: {segment} leaves the arm's reach {at}")
        self._refuse_limit(q, frame, tau)
        sigma = self._sigma_bound(self.kin.jacobian_rows(q, self.tcp))
        if sigma < SINGULARITY_LIMIT:
            name = _singularity_name(self.kin, q)
            segment, at = _where(self.path, tau, frame)
            raise GoalRejected(
                f"linear goal: {segment} passes through {name} {at} "
                f"(smallest singular value {sigma:.3g}, below {SINGULARITY_LIMIT:.3g})"
            )
        step = math.sqrt(sum((a - b) ** 2 for a, b in zip(q, prev, strict=True)))
        cartesian = _cartesian_step(self._frame, frame)
        allowed = FLIP_RATIO * cartesian / min(sigma, self._sigma) + 1e-9
        if step > allowed:
            self._refuse_limit(self._extrapolated(), frame, tau)
            worst = max(range(len(q)), key=lambda i: abs(q[i] - prev[i]))
            segment, at = _where(self.path, tau, frame)
            raise GoalRejected(
                f"linear goal: {segment} flips the arm's branch {at}: "
                f"{self.limits.names[worst]} would jump {q[worst] - prev[worst]:.4g} rad in one cycle"
            )
        self._sigma = sigma
        configuration = _configuration(self.kin, q)
        if configuration != self._configuration:
            if self._configuration is not None and configuration is not None:
                segment, at = _where(self.path, tau, frame)
                raise GoalRejected(
                    f"linear goal: {segment} flips the arm's branch {at}: its configuration would change "
                    f"from {', '.join(self._configuration)} to {', '.join(configuration)}"
                )
            self._configuration = configuration

    def _sigma_bound(self, rows: list[list[float]]) -> float:
        """A lower bound of the smallest singular value at ``rows``, exact where it matters.

        sigma_min moves by at most the Frobenius norm of the Jacobian's change (Weyl), so after one
        exact value (``dls.singularity``, ~50 µs) the next samples take it less that distance (~3 µs)
        until the bound falls below half the exact value or near ``SINGULARITY_LIMIT``."""
        ref = self._ref_rows
        if ref is not None:
            drift = math.sqrt(
                sum(
                    (a - b) * (a - b)
                    for row, ref_row in zip(rows, ref, strict=True)
                    for a, b in zip(row, ref_row, strict=True)
                )
            )
            bound = self._ref_sigma - drift
            if bound >= 0.5 * self._ref_sigma and bound >= 2.0 * SINGULARITY_LIMIT:
                return bound
        self._ref_rows = rows
        self._ref_sigma = singularity(rows)
        return self._ref_sigma

    def _extrapolated(self) -> tuple[float, ...]:
        """Where the joints were heading: the last sample plus its last step."""
        a, b = self._q[-1], self._q[-2]
        return tuple(2.0 * x - y for x, y in zip(a, b, strict=True))

    def _refuse_limit(self, q: Sequence[float], frame: Frame, tau: float) -> None:
        limits = self.limits
        for i, value in enumerate(q):
            lo, hi = limits.min_position[i], limits.max_position[i]
            if not lo - 1e-12 <= value <= hi + 1e-12:
                segment, at = _where(self.path, tau, frame)
                raise GoalRejected(
                    f"linear goal: {segment}: {limits.names[i]} would leave its limits {at}: it would reach "
                    f"{value:.4g}, outside [{lo:.4g}, {hi:.4g}]"
                )

    def _differences(self, q: tuple[float, ...], frame: Frame, tau: float) -> None:
        """The finite differences ending at this sample, against the limits (retiming if over)."""
        h = self.period
        qs = self._q
        qs.append(q)
        del qs[0]
        for i in range(len(q)):
            d1 = qs[3][i] - qs[2][i]
            d2 = d1 - (qs[2][i] - qs[1][i])
            d3 = d2 - (qs[2][i] - 2.0 * qs[1][i] + qs[0][i])
            for m, d in enumerate((d1, d2, d3)):
                value = abs(d) / h ** (m + 1)
                limit = self._joint_limits[m][i] * (1.0 + LIMIT_TOLERANCE) + self._joint_noise[m]
                if value > limit:
                    what = f"{self.limits.names[i]} {_ORDERS[m]}"
                    self.worst.offer(
                        (value / limit) ** (1.0 / (m + 1)), what, value, self._joint_limits[m][i], tau, frame
                    )
        self._cartesian_differences(frame, tau)

    def _cartesian_differences(self, frame: Frame, tau: float) -> None:
        h = self.period
        xs = self._x
        xs.append((frame[9], frame[10], frame[11]))
        del xs[0]
        ws = self._w
        turn = rotation_vector(*compose(frame, inverse(self._frame))[:9])
        ws.append((turn[0] / h, turn[1] / h, turn[2] / h))
        del ws[0]
        linear = (
            [xs[3][c] - xs[2][c] for c in range(3)],
            [xs[3][c] - 2.0 * xs[2][c] + xs[1][c] for c in range(3)],
            [xs[3][c] - 3.0 * xs[2][c] + 3.0 * xs[1][c] - xs[0][c] for c in range(3)],
        )
        angular = (
            [ws[2][c] * h for c in range(3)],
            [(ws[2][c] - ws[1][c]) * h for c in range(3)],
            [(ws[2][c] - 2.0 * ws[1][c] + ws[0][c]) * h for c in range(3)],
        )
        for m in range(3):
            scale = h ** (m + 1)
            for name, diffs, limits in (
                ("TCP", linear, self._linear),
                ("TCP angular", angular, self._angular),
            ):
                value = math.sqrt(sum(d * d for d in diffs[m])) / scale
                limit = limits[m] * (1.0 + LIMIT_TOLERANCE) + self._pose_noise[m]
                if value > limit:
                    self.worst.offer(
                        (value / limit) ** (1.0 / (m + 1)),
                        f"{name} {_ORDERS[m]}",
                        value,
                        limits[m],
                        tau,
                        frame,
                    )


def _cartesian_step(a: Frame, b: Frame) -> float:
    """The 6-vector norm of the step from frame ``a`` to ``b``: displacement (m) and rotation (rad)."""
    turn = rotation_vector(*compose(b, inverse(a))[:9])
    return math.sqrt(
        (b[9] - a[9]) ** 2
        + (b[10] - a[10]) ** 2
        + (b[11] - a[11]) ** 2
        + turn[0] ** 2
        + turn[1] ** 2
        + turn[2] ** 2
    )


def _singularity_name(kin: ArmKinematics, q: Sequence[float]) -> str:
    """'a wrist singularity' (elbow, shoulder) for arms with named configurations, else 'a singularity'."""
    name_of = getattr(kin, "singularity_name", None) if kin.branches else None
    if name_of is None:
        return "a singularity"
    name = str(name_of(q))
    return f"{'an' if name[:1] in 'aeiou' else 'a'} {name} singularity"


_BRANCH_GROUPS = ("shoulder", "elbow", "wrist")
"""The named configuration's groups (docs/kinematics.md): each changes only where two IK branches meet,
at a singularity, which the singular-value check refuses first unless it falls between two samples."""


def _configuration(kin: ArmKinematics, q: Sequence[float]) -> tuple[str, ...] | None:
    """The branch groups of ``q``'s named configuration (UR arms), else None."""
    configuration_of = getattr(kin, "configuration_of", None) if kin.branches else None
    if configuration_of is None:
        return None
    named = configuration_of(q)
    return tuple(f"{group} {getattr(named, group)}" for group in _BRANCH_GROUPS)
