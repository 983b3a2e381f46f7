"""Linear goals (control/linear.py): straight TCP lines, within every limit, checked before motion.

Arms: a nominal UR5e, a UR5e with a random calibration (seeded) and a UR10e with a real calibration;
the path is measured with the test-side DH forward kinematics (``support.dh_fk``), independent of the
planner's. Finite differences are checked at every cycle with the tolerance linear.py documents:
``LIMIT_TOLERANCE`` relative plus ``2^m * JOINT_NOISE / h^m`` for joints (the IK's accuracy).
New module: every test here fails on the code before it (no control/linear.py).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Generator, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pytest

from tests.control.sim import SimRobot
from tests.description.support import REAL_UR10E, dh_fk, random_calibration
from tests.description.test_chain import SIX, _custom
from tests.helpers import Stepped
from urdaemon.control import GoalStatus
from urdaemon.control.cartesian import CartesianLimits
from urdaemon.control.linear import (
    JOINT_NOISE,
    LIMIT_TOLERANCE,
    MAX_SLOWDOWN,
    plan_linear,
)
from urdaemon.control.sampled import SampledTrajectory
from urdaemon.control.scaling import planning_limits
from urdaemon.daemon import describe_cell
from urdaemon.description import DhParameters, UrKinematics, load_ur_model
from urdaemon.description.chain import ChainKinematics
from urdaemon.description.frames import compose, frame_of_pose, rotation_vector
from urdaemon.description.ik_types import run_steps
from urdaemon.errors import GoalRejected
from urdaemon.model import UR_JOINTS, JointLimits

PERIOD = 0.002
CARTESIAN = CartesianLimits(0.25, 1.2, 10.0, 1.0, 4.0, 40.0)
TCP = (0.01, -0.02, 0.12, 0.1, -0.2, 0.3)
Q0 = (0.3, -1.2, 1.5, -1.9, -1.5, 0.4)
"""Clear of singularities on every arm here."""


def _model_limits(name: str) -> JointLimits:
    model = load_ur_model(name)
    return JointLimits(
        names=UR_JOINTS,
        min_position=tuple(-math.inf if j.min_position is None else j.min_position for j in model.joints),
        max_position=tuple(math.inf if j.max_position is None else j.max_position for j in model.joints),
        max_velocity=tuple(j.max_velocity for j in model.joints),
        max_acceleration=tuple(j.max_acceleration for j in model.joints),
        max_jerk=tuple(j.max_jerk for j in model.joints),
    )


ARMS = {
    "ur5e-nominal": ("ur5e", None),
    "ur5e-random-calibration": (
        "ur5e",
        random_calibration(load_ur_model("ur5e").dh, np.random.default_rng(17)),
    ),
    "ur10e-real-calibration": ("ur10e", REAL_UR10E),
}


def _arm(key: str) -> tuple[UrKinematics, DhParameters, JointLimits]:
    name, dh = ARMS[key]
    model = load_ur_model(name)
    return UrKinematics(model, dh), dh or model.dh, planning_limits(_model_limits(name))


def _matrix(pose: Sequence[float]) -> np.ndarray:
    f = frame_of_pose(pose)
    m = np.eye(4)
    m[:3, :3] = np.array(f[:9]).reshape(3, 3)
    m[:3, 3] = f[9:]
    return m


def _tcp_frame(dh: DhParameters, q: Sequence[float], tcp: Sequence[float] = TCP) -> np.ndarray:
    """The TCP frame by the test-side DH chain (the controller's base is the DH base)."""
    frame: np.ndarray = dh_fk(dh, np.asarray(q, dtype=float)) @ _matrix(tcp)
    return frame


def _samples(plan: SampledTrajectory) -> list[tuple[float, ...]]:
    """The joints commanded at every cycle, as the goal run samples them."""
    pos, vel, acc = [0.0] * 6, [0.0] * 6, [0.0] * 6
    out = []
    for n in range(round(plan.duration / PERIOD) + 1):
        plan.sample(n * PERIOD, pos, vel, acc)
        out.append(tuple(pos))
    return out


def _offset(
    pose: Sequence[float], dx: float, dy: float, dz: float, turn: Sequence[float] = (0, 0, 0)
) -> tuple[float, ...]:
    """``pose`` moved by (dx, dy, dz) and turned by ``turn`` (rotation vector, base)."""
    f = compose(frame_of_pose((0.0, 0.0, 0.0, *turn)), frame_of_pose(pose))
    rx, ry, rz = rotation_vector(*f[:9])
    return (pose[0] + dx, pose[1] + dy, pose[2] + dz, rx, ry, rz)


def _plan(
    kin: Any, start: Sequence[float], poses: Any, blends: Sequence[float] = (), **kw: Any
) -> SampledTrajectory:
    limits = kw.pop("limits", None)
    return run_steps(
        plan_linear(
            kin, start, poses, blends, kw.pop("tcp", TCP), kw.pop("cartesian", CARTESIAN), limits, PERIOD
        )
    )


def _distance_to_line(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    u = (b - a) / np.linalg.norm(b - a)
    d = p - a
    return float(np.linalg.norm(d - np.dot(d, u) * u))


def _check_differences(samples: list[tuple[float, ...]], limits: JointLimits) -> float:
    """Assert joint velocity, acceleration and jerk at every cycle (at rest before and after); the
    largest share of a limit used."""
    q = np.array([samples[0]] * 3 + samples + [samples[-1]] * 3)
    worst = 0.0
    for m, bound in enumerate((limits.max_velocity, limits.max_acceleration, limits.max_jerk), start=1):
        diff = np.diff(q, n=m, axis=0) / PERIOD**m
        allowed = np.array(bound) * (1 + LIMIT_TOLERANCE) + 2**m * JOINT_NOISE / PERIOD**m
        over = np.abs(diff) / allowed
        assert over.max() <= 1.0, (
            f"order {m}: {over.max()} of the limit at cycle {int(over.max(axis=1).argmax())}"
        )
        worst = max(worst, float(over.max()))
    return worst


def _check_cartesian(frames: list[np.ndarray], cartesian: CartesianLimits) -> None:
    """Assert the TCP's speed, acceleration, jerk and angular ones at every cycle (finite differences)."""
    x = np.array([frames[0][:3, 3]] * 3 + [f[:3, 3] for f in frames] + [frames[-1][:3, 3]] * 3)
    for m, bound in enumerate((cartesian.speed, cartesian.acceleration, cartesian.jerk), start=1):
        value = np.linalg.norm(np.diff(x, n=m, axis=0), axis=1) / PERIOD**m
        assert value.max() <= bound * (1 + LIMIT_TOLERANCE) + 1e-6, f"TCP order {m}: {value.max()} > {bound}"
    omega = [np.zeros(3)] * 3
    for a, b in itertools.pairwise(frames):
        r = b[:3, :3] @ a[:3, :3].T
        omega.append(np.array(rotation_vector(*r.reshape(9))) / PERIOD)
    omega += [np.zeros(3)] * 3
    w = np.array(omega)
    for m, bound in enumerate(
        (cartesian.angular_speed, cartesian.angular_acceleration, cartesian.angular_jerk)
    ):
        value = np.linalg.norm(np.diff(w, n=m, axis=0), axis=1) / PERIOD**m
        assert value.max() <= bound * (1 + LIMIT_TOLERANCE) + 1e-5, (
            f"angular order {m}: {value.max()} > {bound}"
        )


@pytest.mark.parametrize("key", list(ARMS))
def test_the_tcp_follows_the_straight_line_and_ends_at_the_pose(key: str) -> None:
    kin, dh, limits = _arm(key)
    start_pose = kin.forward(Q0, TCP)
    goal = _offset(start_pose, 0.15, -0.1, 0.08, (0.2, -0.1, 0.3))
    plan = _plan(kin, Q0, [goal], limits=limits)
    assert plan.slowed_by == 1.0  # runs as asked; the duration is only rounded up to a whole cycle
    samples = _samples(plan)
    assert samples[0] == Q0
    a, b = _matrix(start_pose), _matrix(goal)
    turn = np.array(rotation_vector(*(b[:3, :3] @ a[:3, :3].T).reshape(9)))
    for q in samples:
        f = _tcp_frame(dh, q)
        assert _distance_to_line(f[:3, 3], a[:3, 3], b[:3, 3]) < 1e-6
        # The orientation turns about the one axis of the shortest rotation from start to goal.
        w = np.array(rotation_vector(*(f[:3, :3] @ a[:3, :3].T).reshape(9)))
        assert np.linalg.norm(np.cross(w, turn)) < 1e-6 * np.linalg.norm(turn)
    # Between two cycles (the speed slider slows trajectory time) the interpolation stays on the line.
    pos, vel, acc = [0.0] * 6, [0.0] * 6, [0.0] * 6
    for n in range(0, len(samples) - 1, 7):
        plan.sample((n + 0.5) * PERIOD, pos, vel, acc)
        assert _distance_to_line(_tcp_frame(dh, pos)[:3, 3], a[:3, 3], b[:3, 3]) < 1e-6
    end = _tcp_frame(dh, samples[-1])
    assert np.linalg.norm(end[:3, 3] - b[:3, 3]) < 1e-9
    assert np.linalg.norm(rotation_vector(*(end[:3, :3] @ b[:3, :3].T).reshape(9))) < 1e-9
    assert plan.final_positions == samples[-1]


@pytest.mark.parametrize("key", list(ARMS))
def test_joint_and_cartesian_limits_hold_at_every_cycle(key: str) -> None:
    kin, dh, limits = _arm(key)
    start_pose = kin.forward(Q0, TCP)
    p1 = _offset(start_pose, 0.2, 0.05, -0.05, (0.0, 0.0, 0.4))
    p2 = _offset(p1, -0.05, -0.2, 0.1, (0.2, 0.0, 0.0))
    plan = _plan(kin, Q0, [p1, p2], [0.04], limits=limits)
    samples = _samples(plan)
    _check_differences(samples, limits)
    _check_cartesian([_tcp_frame(dh, q) for q in samples], CARTESIAN)


def test_a_fast_path_near_a_singularity_is_slowed_to_keep_the_joint_limits() -> None:
    """Near the wrist singularity (wrist_2 at 0.1 rad) 1 m/s needs wrist joints faster than their
    limits: the whole plan is retimed uniformly, says by how much, and keeps every limit."""
    kin, dh, limits = _arm("ur5e-nominal")
    q = (0.3, -1.2, 1.5, -1.9, 0.12, 0.4)
    start_pose = kin.forward(q, TCP)
    fast = CartesianLimits(1.0, 5.0, 50.0, 3.0, 15.0, 150.0)
    goal = _offset(start_pose, 0.0, 0.1, 0.0)
    plan = _plan(kin, q, [goal], limits=limits, cartesian=fast)
    assert 1.05 < plan.slowed_by <= MAX_SLOWDOWN
    worst = _check_differences(_samples(plan), limits)
    assert worst > 0.9  # retimed just enough: some joint limit is nearly reached
    _check_cartesian([_tcp_frame(dh, s) for s in _samples(plan)], fast)


def test_a_blend_stays_within_its_radius_and_leaves_the_corner() -> None:
    kin, dh, limits = _arm("ur5e-random-calibration")
    start_pose = kin.forward(Q0, TCP)
    corner = _offset(start_pose, 0.2, 0.0, 0.0)
    end = _offset(corner, 0.0, 0.2, 0.0)
    radius = 0.05
    plan = _plan(kin, Q0, [corner, end], [radius], limits=limits)
    a, c, b = (_matrix(p)[:3, 3] for p in (start_pose, corner, end))
    nearest = math.inf
    for q in _samples(plan):
        p = _tcp_frame(dh, q)[:3, 3]
        to_corner = float(np.linalg.norm(p - c))
        nearest = min(nearest, to_corner)
        on_a_line = min(_distance_to_line(p, a, c), _distance_to_line(p, c, b)) < 1e-6
        assert on_a_line or to_corner <= radius + 1e-9
        if not on_a_line:
            assert to_corner > 0.0
    # The blend rounds the corner off: the TCP passes it at a distance.
    assert nearest > 0.1 * radius
    unblended = _plan(kin, Q0, [corner, end], [0.0], limits=limits)
    assert plan.duration < unblended.duration


def test_a_zero_radius_stops_at_the_pose() -> None:
    """No blend: the TCP stays on the two lines and comes to rest at the corner (between two cycles,
    so the nearest sample is within jerk * h^3 / 6, ~1.3e-8 m, of it)."""
    kin, dh, limits = _arm("ur5e-nominal")
    start_pose = kin.forward(Q0, TCP)
    corner = _offset(start_pose, 0.2, 0.0, 0.0)
    end = _offset(corner, 0.0, 0.2, 0.0)
    plan = _plan(kin, Q0, [corner, end], [0.0], limits=limits)
    a, c, b = (_matrix(p)[:3, 3] for p in (start_pose, corner, end))
    points = [_tcp_frame(dh, q)[:3, 3] for q in _samples(plan)]
    for p in points:
        assert min(_distance_to_line(p, a, c), _distance_to_line(p, c, b)) < 1e-6
    closest = min(range(len(points)), key=lambda n: float(np.linalg.norm(points[n] - c)))
    assert np.linalg.norm(points[closest] - c) < CARTESIAN.jerk * PERIOD**3 / 6
    step = np.linalg.norm(points[closest + 1] - points[closest - 1]) / (2 * PERIOD)
    assert step < 1e-4  # at rest there (m/s)


def _refusal(plan: Generator[None, None, SampledTrajectory]) -> tuple[str, int]:
    """The reason a plan refuses and the steps it took."""
    check = Stepped(plan)
    for steps in range(100_000):
        try:
            more = check.step(1)
        except GoalRejected as exc:
            return str(exc), steps
        assert more, "the check finished without refusing"
    raise AssertionError("the check never ended")


def test_a_pose_out_of_reach_is_refused_before_sampling() -> None:
    kin, _, limits = _arm("ur5e-nominal")
    near = _offset(kin.forward(Q0, TCP), 0.05, 0.0, 0.0)
    far = (2.5, 0.0, 0.3, 0.0, 3.14, 0.0)
    reason, steps = _refusal(plan_linear(kin, Q0, [near, far], [0.0], TCP, CARTESIAN, limits, PERIOD))
    assert reason == "linear goal: pose 1 is out of reach (no joint solution within the limits)"
    # pose 0 checked (its IK's chunks and one step), pose 1's IK's chunks, refused: nothing sampled
    q_near, near_chunks = _chunks(kin.nearest_steps(near, Q0, TCP))
    _, far_chunks = _chunks(kin.nearest_steps(far, q_near, TCP))
    assert steps == near_chunks + 1 + far_chunks


def _chunks(steps: Any) -> tuple[Any, int]:
    """What an IK generator returns and how many times it yields (its chunks but the last)."""
    count = 0
    while True:
        try:
            next(steps)
        except StopIteration as stop:
            return stop.value, count
        count += 1


def test_a_path_through_the_wrist_singularity_is_refused_naming_where() -> None:
    kin, _, limits = _arm("ur5e-nominal")
    qa = (0.3, -1.2, 1.5, -1.9, 0.3, 0.4)
    qb = (0.3, -1.2, 1.5, -1.9, -0.3, 0.4)
    goal = kin.forward(qb, TCP)
    check = plan_linear(kin, qa, [goal], [], TCP, CARTESIAN, limits, PERIOD)
    reason, _ = _refusal(check)
    assert reason.startswith("linear goal: segment 0 passes through a wrist singularity at ")
    assert "% (x, y, z = " in reason
    assert "m in base)" in reason


def test_a_path_leaving_the_joint_limits_is_refused_naming_the_joint_and_where() -> None:
    kin, _, model = _arm("ur5e-nominal")
    low = list(model.min_position)
    high = list(model.max_position)
    low[0], high[0] = Q0[0] - 0.2, Q0[0] + 0.2  # shoulder_pan_joint within +-0.2 rad of the start
    limits = JointLimits(
        model.names, tuple(low), tuple(high), model.max_velocity, model.max_acceleration, model.max_jerk
    )
    # The goal turns the pan 0.35 rad: the line crosses the limit on the way.
    goal = kin.forward((Q0[0] + 0.35, *Q0[1:]), TCP)
    reason, steps = _refusal(plan_linear(kin, Q0, [goal], [], TCP, CARTESIAN, limits, PERIOD))
    assert reason.startswith("linear goal: segment 0: shoulder_pan_joint would leave its limits at ")
    assert "x, y, z = " in reason
    assert "outside [0.1, 0.5]" in reason
    assert steps > 2  # found while sampling, before any motion


class _FlippingArm:
    """A UR5e whose IK answers with another branch past x = ``flip_x``: a branch flip."""

    def __init__(self, kin: UrKinematics, flip_x: float) -> None:
        self._kin = kin
        self._flip_x = flip_x
        self.dof = 6
        self.branches = True

    def forward(self, q: Any, tcp: Any = None) -> Any:
        return self._kin.forward(q, tcp)

    def jacobian_rows(self, q: Any, tcp: Any = None) -> list[list[float]]:
        return self._kin.jacobian_rows(q, tcp)

    def nearest_steps(self, pose: Any, qnear: Any, tcp: Any = None, *args: Any) -> Any:
        """``nearest`` in one chunk (what the subclasses' ``nearest`` answers)."""
        yield from ()  # a generator of one chunk, run by the check's steps as a real arm's chunks are
        return self.nearest(pose, qnear, tcp)

    def nearest(self, pose: Any, qnear: Any, tcp: Any = None, *args: Any) -> Any:
        q = self._kin.nearest(pose, qnear, tcp)
        if q is None or pose[0] < self._flip_x:
            return q
        others = [
            s.q
            for s in self._kin.solutions(pose, tcp, qnear)
            if max(abs(a - b) for a, b in zip(s.q, q, strict=True)) > 0.5
        ]
        return others[0]


def test_a_branch_flip_is_refused_naming_where() -> None:
    kin, _, limits = _arm("ur5e-nominal")
    start_pose = kin.forward(Q0, TCP)
    goal = _offset(start_pose, 0.2, 0.0, 0.0)
    arm = _FlippingArm(kin, start_pose[0] + 0.1)
    # The goal pose itself is reachable by the flipping arm's other branch: only sampling finds the jump.
    reason, _ = _refusal(plan_linear(arm, Q0, [goal], [], TCP, CARTESIAN, limits, PERIOD))
    assert reason.startswith("linear goal: segment 0 flips the arm's branch at ")
    assert "rad in one cycle" in reason


class _ShortArm(_FlippingArm):
    """A UR5e whose IK finds nothing for x in 3 cm past ``flip_x``: a line leaving the reach."""

    def nearest(self, pose: Any, qnear: Any, tcp: Any = None, *args: Any) -> Any:
        outside = self._flip_x < pose[0] < self._flip_x + 0.03
        return None if outside else self._kin.nearest(pose, qnear, tcp)


def test_a_line_leaving_the_reach_is_refused_naming_where() -> None:
    kin, _, limits = _arm("ur5e-nominal")
    start_pose = kin.forward(Q0, TCP)
    goal = _offset(start_pose, 0.2, 0.0, 0.0)
    back = _offset(start_pose, 0.05, 0.0, 0.0)
    # Both poses are in reach; the line between them runs out of it from x + 0.12 to x + 0.15.
    arm = _ShortArm(kin, start_pose[0] + 0.12)
    reason, _ = _refusal(plan_linear(arm, Q0, [back, goal], [0.0], TCP, CARTESIAN, limits, PERIOD))
    assert reason.startswith("linear goal: segment 1 leaves the arm's reach at ")
    assert "(x, y, z = " in reason


def test_turning_in_place_keeps_the_tcp_point_and_the_angular_limits() -> None:
    kin, dh, limits = _arm("ur5e-random-calibration")
    start_pose = kin.forward(Q0, TCP)
    goal = _offset(start_pose, 0.0, 0.0, 0.0, (0.0, 0.3, 0.6))
    plan = _plan(kin, Q0, [goal], limits=limits)
    frames = [_tcp_frame(dh, q) for q in _samples(plan)]
    for f in frames:
        assert np.linalg.norm(f[:3, 3] - np.array(start_pose[:3])) < 1e-6
    _check_cartesian(frames, CARTESIAN)
    # Timed by the angular limits alone: 0.67 rad at 1 rad/s takes more than 0.67 s.
    assert plan.duration > math.hypot(0.3, 0.6) / CARTESIAN.angular_speed


def test_a_goal_that_would_need_more_than_the_largest_slowdown_is_refused() -> None:
    """Joints limited to 0.02 rad/s cannot follow 0.25 m/s: 10 times slower is not enough."""
    kin, _, model = _arm("ur5e-nominal")
    limits = JointLimits(
        model.names,
        model.min_position,
        model.max_position,
        (0.02,) * 6,
        model.max_acceleration,
        model.max_jerk,
    )
    goal = _offset(kin.forward(Q0, TCP), 0.2, 0.0, 0.0)
    reason, _ = _refusal(plan_linear(kin, Q0, [goal], [], TCP, CARTESIAN, limits, PERIOD))
    assert reason.startswith("linear goal: it would have to run ")
    assert "times slower than asked (at most 10): on segment 0 at " in reason
    assert "velocity would be " in reason


class _Named(NamedTuple):
    shoulder: str
    elbow: str
    wrist: str


class _RenamingArm(_FlippingArm):
    """A UR5e whose configuration reads wrist "up" past x = ``flip_x`` (joints continuous)."""

    def nearest(self, pose: Any, qnear: Any, tcp: Any = None, *args: Any) -> Any:
        return self._kin.nearest(pose, qnear, tcp)

    def configuration_of(self, q: Any) -> _Named:
        past = self._kin.forward(q, TCP)[0] > self._flip_x
        return _Named("right", "up", "up" if past else "down")


def test_a_configuration_change_is_a_branch_flip() -> None:
    kin, _, limits = _arm("ur5e-nominal")
    start_pose = kin.forward(Q0, TCP)
    arm = _RenamingArm(kin, start_pose[0] + 0.1)
    goal = _offset(start_pose, 0.2, 0.0, 0.0)
    reason, _ = _refusal(plan_linear(arm, Q0, [goal], [], TCP, CARTESIAN, limits, PERIOD))
    assert reason.startswith("linear goal: segment 0 flips the arm's branch at ")
    assert reason.endswith(
        "its configuration would change from shoulder right, elbow up, wrist down to shoulder right, "
        "elbow up, wrist up"
    )


def test_a_sound_path_keeps_its_configuration() -> None:
    """A sound path (continuous joints, clear of singularities) is planned though the configuration is
    compared every cycle. Reproduction: with the elbow named by joint 4's side of the shoulder (before
    ik.py's 0d76271) the name changed on this square's second side and the path was refused."""
    kin, _, limits = _arm("ur5e-nominal")
    q = (0.0, -1.2, 1.2, -1.57, -1.57, 0.0)
    start_pose = kin.forward(q, TCP)
    p1 = _offset(start_pose, 0.5, 0.0, 0.0)
    p2 = _offset(p1, 0.0, 0.5, 0.0)
    plan = _plan(kin, q, [p1, p2], [0.0], limits=limits)
    assert {kin.configuration_of(s) for s in _samples(plan)} == {kin.configuration_of(q)}


class _CountingArm(_FlippingArm):
    """Counts the IK calls."""

    def __init__(self, kin: UrKinematics) -> None:
        super().__init__(kin, math.inf)
        self.calls = 0

    def nearest(self, pose: Any, qnear: Any, tcp: Any = None, *args: Any) -> Any:
        self.calls += 1
        return super().nearest(pose, qnear, tcp)


def test_a_long_path_plans_in_bounded_steps() -> None:
    """A 2 m square with blended corners on a calibrated UR10e: each step does at most one IK, and
    the steps are one per pose, one per segment and two per sample of each pass (at most four)."""
    kin, _, limits = _arm("ur10e-real-calibration")
    arm = _CountingArm(kin)
    q = (0.0, -1.2, 1.2, -1.57, -1.57, 0.0)
    start_pose = kin.forward(q, TCP)
    p1 = _offset(start_pose, 0.5, 0.0, 0.0)
    p2 = _offset(p1, 0.0, 0.5, 0.0)
    p3 = _offset(p2, -0.5, 0.0, 0.0)
    p4 = _offset(p3, 0.0, -0.5, 0.0)
    check = Stepped(plan_linear(arm, q, [p1, p2, p3, p4], [0.05, 0.05, 0.05], TCP, CARTESIAN, limits, PERIOD))
    steps = 0
    most = 0
    more = True
    while more and steps < 100_000:
        before = arm.calls
        more = check.step(1)
        steps += 1
        most = max(most, arm.calls - before)
    plan = check.result()
    assert most == 1
    assert plan.duration > 8.0  # 2 m at 0.25 m/s
    # IK calls: the 4 poses, then every sample but the first of each pass. Steps: the 4 poses, the 4
    # segments, per pass its first sample and two for each other (the IK, the checks), and the last
    # call that ends the check.
    passes = steps - 9 - 2 * (arm.calls - 4)
    assert 1 <= passes <= 4


def test_the_plan_runs_on_the_controller_and_succeeds_at_the_last_pose() -> None:
    kin, _, _ = _arm("ur5e-nominal")
    goal = _offset(kin.forward(Q0, TCP), 0.1, 0.05, 0.0)
    robot = SimRobot.create(_model_limits("ur5e"), list(Q0))
    plan = _plan(kin, Q0, [goal], limits=robot.controller.plan_limits)
    duration = robot.controller.accept_planned("g1", plan, robot.state, robot.now)
    assert duration == plan.duration
    result = robot.run_until_result("g1", round(plan.duration / PERIOD) + 200)
    assert result.status is GoalStatus.SUCCEEDED
    commanded = [c[1] for c in robot.commands if c[1] != tuple(robot.commands[0][1])]
    assert commanded[-1] == pytest.approx(plan.final_positions, abs=1e-12)
    assert np.linalg.norm(np.array(kin.forward(robot.state.positions, TCP)[:3]) - goal[:3]) < 1e-9


def test_a_goal_at_the_start_pose_is_a_plan_of_no_time() -> None:
    kin, _, limits = _arm("ur5e-nominal")
    plan = _plan(kin, Q0, [kin.forward(Q0, TCP)], limits=limits)
    assert plan.duration == 0.0
    assert plan.final_positions == Q0


@pytest.mark.parametrize(
    ("poses", "blends", "reason"),
    [
        ([], [], "linear goal: poses must hold 1 to 1000 poses, got 0"),
        (
            [(0.3, 0.1, 0.4, 0.0, 3.1)],
            [],
            "linear goal: pose 0 must be 6 finite numbers (x, y, z, rx, ry, rz)",
        ),
        (
            [(0.3, 0.1, math.nan, 0.0, 3.1, 0.0)],
            [],
            "linear goal: pose 0 must be 6 finite numbers (x, y, z, rx, ry, rz)",
        ),
        (
            [(0.3, 0.1, 0.4, 0.0, 3.1, 0.0)] * 2,
            [0.1, 0.1],
            "linear goal: blend_radii must hold one radius per pose but the last (1), got 2",
        ),
        (
            [(0.3, 0.1, 0.4, 0.0, 3.1, 0.0)] * 2,
            [-0.1],
            "linear goal: blend radius 0 must be a finite number >= 0, got -0.1",
        ),
    ],
)
def test_malformed_arguments_are_refused(poses: Any, blends: Any, reason: str) -> None:
    kin, _, limits = _arm("ur5e-nominal")
    got, steps = _refusal(plan_linear(kin, Q0, poses, blends, TCP, CARTESIAN, limits, PERIOD))
    assert got == reason
    assert steps == 0


def test_a_custom_robots_pose_out_of_reach_is_checked_one_evaluation_per_step(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A custom robot's numeric IK tries nine starts for a pose out of reach (2-4 ms at once); the
    check takes it one chain evaluation per step, so the runtime's 0.25 ms slice can split it.
    Reproduction: before nearest_steps the whole IK was one step (hundreds of evaluations)."""
    _, kin = _custom(tmp_path, SIX)
    limits = describe_cell(_custom(tmp_path, SIX)[0]).limits["arm"]
    walks = [0]
    walk = ChainKinematics._walk

    def counted(self: ChainKinematics, q: Any, rows: Any) -> Any:
        walks[0] += 1
        return walk(self, q, rows)

    monkeypatch.setattr(ChainKinematics, "_walk", counted)
    q0 = [0.1] * kin.dof
    for poses in ([(5.0, 0.0, 0.0, 0.0, 0.0, 0.0)], [kin.forward(q0), (5.0, 0.0, 0.0, 0.0, 0.0, 0.0)]):
        check = Stepped(
            plan_linear(kin, q0, poses, [0.0] * (len(poses) - 1), (0.0,) * 6, CARTESIAN, limits, PERIOD)
        )
        most, steps, reason = 0, 0, ""
        while not reason and steps < 100_000:
            before = walks[0]
            try:
                assert check.step(1), "the check finished without refusing"
            except GoalRejected as exc:
                reason = str(exc)
            most = max(most, walks[0] - before)
            steps += 1
        assert reason.startswith(f"linear goal: pose {len(poses) - 1} is out of reach")
        assert most <= 1
        assert steps >= 50
