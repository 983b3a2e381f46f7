"""Inverse kinematics and the Jacobian (urdaemon.description.ik) against independent references.

References: the test-side DH forward kinematics (``support.dh_fk``), finite differences, and the
``ur_analytic_ik`` package (nominal models). Calibrations: a real UR10e's and random ones with the
real arms' huge opposite d2/d3. New module: every test here fails on the code before it (no ik.py).
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys

import numpy as np
import pytest
import ur_analytic_ik

from urdaemon.cell import ur_models
from urdaemon.description import DhParameters, UrKinematics, load_ur_model
from urdaemon.description.dls import singularity
from urdaemon.description.ik import frame_of_pose, pose_of_frame
from urdaemon.description.ik_types import Vector
from urdaemon.description.kinematics import dh_chain, dh_joints
from urdaemon.description.ur_closed_form import ELBOW, WRIST
from urdaemon.errors import DescriptionError

from .support import REAL_UR10E, dh_fk, quat_matrix, random_calibration

Matrix = np.ndarray
GENERIC_Q = (-1.23, -1.67, 1.42, 1.45, 1.51, -0.11)
"""Clear of every singularity; all eight branches reach its pose on every model and calibration."""
TCP = (0.012, -0.02, 0.15, 0.1, -0.2, 0.3)


def _pose_matrix(pose: Vector) -> Matrix:
    """4x4 of a UR pose, built through a quaternion (independent of ik.frame_of_pose)."""
    x, y, z, rx, ry, rz = pose
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    m = np.eye(4)
    if angle > 0.0:
        s = math.sin(angle / 2) / angle
        m[:3, :3] = quat_matrix(rx * s, ry * s, rz * s, math.cos(angle / 2))
    m[:3, 3] = (x, y, z)
    return m


def _tcp_fk(dh: DhParameters, q: Vector, tcp: Vector | None) -> Matrix:
    flange = dh_fk(dh, np.asarray(q, dtype=float))
    return flange if tcp is None else flange @ _pose_matrix(tcp)


def _errors(a: Matrix, b: Matrix) -> tuple[float, float]:
    """Position (m) and orientation (rad) distance between two frames."""
    rotation = a[:3, :3].T @ b[:3, :3]
    cosine = min(1.0, max(-1.0, (np.trace(rotation) - 1.0) / 2.0))
    return float(np.linalg.norm(a[:3, 3] - b[:3, 3])), math.acos(cosine)


def _regular(kinematics: UrKinematics, q: Vector) -> bool:
    """q is clear of singularities (smallest singular value of the Jacobian above 0.02)."""
    return float(np.linalg.svd(kinematics.jacobian(q), compute_uv=False)[-1]) > 0.02


def _calibrations(name: str) -> list[DhParameters]:
    nominal = load_ur_model(name).dh
    rng = np.random.default_rng(100 + ur_models().index(name))
    extra = [REAL_UR10E] if name == "ur10e" else []
    return [nominal, random_calibration(nominal, rng), *extra]


def _wrapped_close(a: Vector, b: Vector, tol: float) -> bool:
    d = (np.asarray(a) - np.asarray(b) + math.pi) % (2 * math.pi) - math.pi
    return bool(np.abs(d).max() < tol)


@pytest.mark.parametrize("name", ur_models())
def test_round_trip_on_calibrated_arms(name: str) -> None:
    """Random regular poses (with a TCP) come back to the joints that made them, to 1e-9 m / rad."""
    model = load_ur_model(name)
    rng = np.random.default_rng(ur_models().index(name))
    for dh in _calibrations(name):
        kinematics = UrKinematics(model, dh)
        checked = 0
        for _ in range(200):
            q = rng.uniform(-math.pi, math.pi, 6)
            if not _regular(kinematics, q):
                continue
            pose = kinematics.forward(q, TCP)
            target = _tcp_fk(dh, q, TCP)
            assert _errors(_pose_matrix(pose), target) < (1e-9, 1e-9)
            near = kinematics.nearest(pose, q + rng.uniform(-0.01, 0.01, 6), TCP)
            assert near is not None, f"{name}: no solution for the pose of {q}"
            assert _errors(_tcp_fk(dh, near, TCP), target) < (1e-9, 1e-9)
            np.testing.assert_allclose(near, q, rtol=0, atol=1e-7)
            solutions = kinematics.solutions(pose, TCP, q)
            assert any(np.allclose(s.q, q, rtol=0, atol=1e-7) for s in solutions)
            for solution in solutions:
                assert _errors(_tcp_fk(dh, solution.q, TCP), target) < (1e-9, 1e-9)
            checked += 1
            if checked == 25:
                break
        assert checked == 25


@pytest.mark.parametrize("name", ur_models())
def test_eight_distinct_branches_each_reach_the_pose(name: str) -> None:
    """A generic pose has eight solutions, one per branch, pairwise far apart, each exact."""
    model = load_ur_model(name)
    for dh in _calibrations(name):
        kinematics = UrKinematics(model, dh)
        pose = kinematics.forward(GENERIC_Q)
        target = _tcp_fk(dh, GENERIC_Q, None)
        solutions = kinematics.solutions(pose, qnear=GENERIC_Q)
        assert sorted(s.branch for s in solutions) == list(range(8))
        for i, a in enumerate(solutions):
            assert _errors(_tcp_fk(dh, a.q, None), target) < (1e-10, 1e-10)
            # The branch bits say on which side of the elbow and wrist singularities q3 and q5 are.
            assert (math.sin(a.q[2]) < 0) == bool(a.branch & ELBOW)
            assert (math.sin(a.q[4]) < 0) == bool(a.branch & WRIST)
            for b in solutions[i + 1 :]:
                assert not _wrapped_close(a.q, b.q, 0.05), (a, b)


@pytest.mark.parametrize("name", ur_models())
def test_nearest_picks_the_branch_nearest_qnear(name: str) -> None:
    """From near any branch's joints, nearest() returns that branch, shifted by 2pi toward qnear."""
    model = load_ur_model(name)
    dh = _calibrations(name)[1]
    kinematics = UrKinematics(model, dh)
    pose = kinematics.forward(GENERIC_Q)
    for solution in kinematics.solutions(pose, qnear=GENERIC_Q):
        seed = np.asarray(solution.q) + 0.05
        near = kinematics.nearest(pose, seed)
        assert near is not None
        np.testing.assert_allclose(near, solution.q, rtol=0, atol=1e-9)
    # qnear 2pi away in shoulder_pan (limits +-2pi): the solution follows it.
    seed = np.asarray(GENERIC_Q) + np.array((2 * math.pi, 0, 0, 0, 0, 0))
    near = kinematics.nearest(pose, seed)
    assert near is not None
    np.testing.assert_allclose(near, seed, rtol=0, atol=1e-7)


def test_nearest_stays_within_the_joint_limits() -> None:
    """A qnear beyond a limit gets the nearest solution that is within it (never one outside)."""
    model = load_ur_model("ur5e")
    kinematics = UrKinematics(model, random_calibration(model.dh, np.random.default_rng(3)))
    pose = kinematics.forward(GENERIC_Q)
    # qnear's q1 is 4pi below the pose's: q1 - 4pi and q1 - 2pi are past the -2pi limit.
    seed = (GENERIC_Q[0] - 4 * math.pi, *GENERIC_Q[1:])
    near = kinematics.nearest(pose, seed)
    assert near is not None
    for value, joint in zip(near, model.joints, strict=True):
        assert joint.min_position is not None
        assert joint.max_position is not None
        assert joint.min_position <= value <= joint.max_position
    candidates = kinematics.solutions(pose, qnear=seed)
    assert any(np.allclose(c.q, GENERIC_Q, rtol=0, atol=1e-7) for c in candidates)
    best = min(candidates, key=lambda c: float(np.linalg.norm(np.subtract(c.q, seed))))
    np.testing.assert_allclose(near, best.q, rtol=0, atol=1e-12)
    assert near[0] > -2 * math.pi


def test_a_straight_wrist_gives_q6_the_seed_value() -> None:
    """With q5 = 0 joint 6's axis is parallel to joints 2-4: q6 is free and takes qnear's value."""
    model = load_ur_model("ur10e")
    kinematics = UrKinematics(model)
    q = (0.4, -1.0, 1.2, -1.5, 0.0, 0.7)
    pose = kinematics.forward(q)
    target = _tcp_fk(model.dh, q, None)
    for seed_q6 in (-1.0, 0.0, 2.5):
        seed = (0.4, -1.0, 1.2, -1.5, 0.0, seed_q6)
        straight = [s.q for s in kinematics.solutions(pose, qnear=seed) if abs(math.sin(s.q[4])) < 1e-9]
        assert len(straight) == 4  # both wrist branches coincide, for either elbow, on this shoulder
        for solution in straight:
            assert solution[5] == pytest.approx(seed_q6, abs=1e-12)
            assert _errors(_tcp_fk(model.dh, solution, None), target) < (1e-10, 1e-10)
        near = kinematics.nearest(pose, seed)
        assert near is not None
        assert near[5] == pytest.approx(seed_q6, abs=1e-12)
        assert _errors(_tcp_fk(model.dh, near, None), target) < (1e-10, 1e-10)
    near = kinematics.nearest(pose, q)
    assert near is not None
    np.testing.assert_allclose(near, q, rtol=0, atol=1e-12)


def test_singular_poses_still_solve() -> None:
    """A stretched elbow (q3 = 0) and a straight wrist: solutions exist and are exact."""
    model = load_ur_model("ur5e")
    for dh in (model.dh, random_calibration(model.dh, np.random.default_rng(7))):
        kinematics = UrKinematics(model, dh)
        for q in ((0.2, -1.3, 0.0, -1.0, 1.1, 0.3), (0.2, -1.3, 1.0, -1.0, 0.0, 0.3)):
            pose = kinematics.forward(q)
            near = kinematics.nearest(pose, q)
            assert near is not None
            assert _errors(_tcp_fk(dh, near, None), _tcp_fk(dh, q, None)) < (1e-9, 1e-9)


def test_unreachable_poses_have_no_solution() -> None:
    """Out of reach, or inside the shoulder's cylinder: no solution, has_solution False, nothing made up."""
    kinematics = UrKinematics(
        load_ur_model("ur5e"), random_calibration(load_ur_model("ur5e").dh, np.random.default_rng(1))
    )
    for pose in ((2.0, 0.0, 0.3, 0.0, math.pi, 0.0), (0.0, 0.0, 0.3, 0.0, 0.0, 0.0)):
        assert kinematics.nearest(pose, GENERIC_Q) is None
        assert not kinematics.has_solution(pose, GENERIC_Q)
        assert kinematics.solutions(pose) == []
    # Just beyond reach: the stretched arm's pose moved 10 mm further out from the shoulder.
    stretched = np.array(kinematics.forward((0.3, -0.5, 0.0, -1.0, 1.2, 0.4)))
    outward = stretched[:3] - (0.0, 0.0, load_ur_model("ur5e").dh.d[0])
    stretched[:3] += 0.01 * outward / np.linalg.norm(outward)
    assert kinematics.nearest(stretched, GENERIC_Q) is None
    assert UrKinematics(load_ur_model("ur5e")).nearest(stretched, GENERIC_Q) is None
    reachable = kinematics.forward(GENERIC_Q, TCP)
    assert kinematics.has_solution(reachable, GENERIC_Q, TCP)
    # A tolerance the solution cannot meet (it is ~1e-13 off) is honoured.
    assert not kinematics.has_solution(reachable, GENERIC_Q, TCP, max_position_error=0.0)


@pytest.mark.parametrize("name", ["ur3", "ur5e", "ur10e", "ur30"])
def test_jacobian_matches_finite_differences(name: str) -> None:
    """Each column is the TCP twist of a unit joint speed (central differences of the test-side FK)."""
    model = load_ur_model(name)
    rng = np.random.default_rng(5)
    for dh in _calibrations(name):
        kinematics = UrKinematics(model, dh)
        for _ in range(10):
            q = rng.uniform(-math.pi, math.pi, 6)
            jacobian = kinematics.jacobian(q, TCP)
            assert jacobian.shape == (6, 6)
            h = 1e-6
            for i in range(6):
                step = np.zeros(6)
                step[i] = h
                plus, minus = _tcp_fk(dh, q + step, TCP), _tcp_fk(dh, q - step, TCP)
                linear = (plus[:3, 3] - minus[:3, 3]) / (2 * h)
                spin = (plus[:3, :3] - minus[:3, :3]) / (2 * h) @ _tcp_fk(dh, q, TCP)[:3, :3].T
                angular = np.array((spin[2, 1], spin[0, 2], spin[1, 0]))
                np.testing.assert_allclose(jacobian[:3, i], linear, rtol=0, atol=1e-7)
                np.testing.assert_allclose(jacobian[3:, i], angular, rtol=0, atol=1e-7)


def test_joint_velocity_inverts_the_jacobian_and_is_damped_at_singularities() -> None:
    """Away from singularities J qd = twist exactly; at a straight wrist qd stays bounded."""
    model = load_ur_model("ur10e")
    kinematics = UrKinematics(model, REAL_UR10E)
    twist = np.array((0.05, -0.02, 0.03, 0.1, 0.0, -0.2))
    qd = kinematics.joint_velocity(GENERIC_Q, twist, TCP)
    np.testing.assert_allclose(kinematics.jacobian(GENERIC_Q, TCP) @ qd, twist, rtol=0, atol=1e-12)
    nominal = UrKinematics(model)
    singular = (0.3, -1.2, 1.4, -1.6, 1e-7, 0.5)
    exact = np.linalg.solve(nominal.jacobian(singular), twist)
    damped = nominal.joint_velocity(singular, twist)
    assert np.abs(exact).max() > 1e4  # the undamped inverse would spin the wrist
    assert np.abs(damped).max() < 50.0
    assert np.all(np.isfinite(damped))


@pytest.mark.parametrize("name", ur_models())
def test_agrees_with_ur_analytic_ik_on_nominal_models(name: str) -> None:
    """Our solution set equals the independent package's (mod 2pi), with and without a TCP."""
    solver = getattr(ur_analytic_ik, name)
    model = load_ur_model(name)
    kinematics = UrKinematics(model)
    rng = np.random.default_rng(40 + ur_models().index(name))
    tcp_matrix = _pose_matrix(TCP)
    for _ in range(20):
        q = rng.uniform(-math.pi, math.pi, 6)
        if not _regular(kinematics, q):
            continue
        theirs = solver.inverse_kinematics_with_tcp(
            solver.forward_kinematics_with_tcp(*q, tcp_matrix), tcp_matrix
        )
        ours = kinematics.solutions(kinematics.forward(q, TCP), TCP, q)
        assert len(ours) == len(theirs)
        for solution in ours:
            assert any(_wrapped_close(solution.q, other, 1e-9) for other in theirs)
        closest = solver.inverse_kinematics_closest(solver.forward_kinematics(*q), *q)[0]
        near = kinematics.nearest(kinematics.forward(q), q)
        assert near is not None
        assert _wrapped_close(near, closest, 1e-9)


def test_pose_conversions_round_trip_at_every_angle() -> None:
    """frame_of_pose / pose_of_frame agree with the quaternion route, near 0 and near pi too."""
    rng = np.random.default_rng(9)
    for angle in (0.0, 1e-9, 0.5, 2.0, math.pi - 1e-7, math.pi):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        pose = (0.1, -0.2, 0.3, *(axis * angle))
        frame = frame_of_pose(pose)
        np.testing.assert_allclose(
            np.reshape(frame[:9], (3, 3)), _pose_matrix(pose)[:3, :3], rtol=0, atol=1e-12
        )
        back = pose_of_frame(frame)
        assert _errors(_pose_matrix(back), _pose_matrix(pose)) < (1e-12, 1e-9)


def test_a_non_ur_structure_is_refused() -> None:
    """The closed form needs UR's DH structure (parallel joints 2-4, intersecting wrist offsets)."""
    model = load_ur_model("ur5e")
    bent = dataclasses.replace(
        model,
        dh=dataclasses.replace(model.dh, alpha=(1.5, 0.0, 0.0, 1.5707963267948966, -1.5707963267948966, 0.0)),
    )
    with pytest.raises(DescriptionError, match="ur5e"):
        UrKinematics(bent)


# ---- named configurations (issue 17) ----------------------------------------------------------


@pytest.mark.parametrize("name", ur_models())
def test_each_branch_has_its_own_configuration(name: str) -> None:
    """The eight branches of a pose map to eight distinct configurations; shoulder follows the bit.

    nearest_in asked for each branch's configuration returns that branch (calibrated arm too).
    Reproduction: before issue 17 there was no configuration_of / nearest_in."""
    from urdaemon.description.configurations import configuration_of
    from urdaemon.description.ur_closed_form import SHOULDER

    model = load_ur_model(name)
    for dh in _calibrations(name)[:2]:
        kinematics = UrKinematics(model, dh)
        pose = kinematics.forward(GENERIC_Q, TCP)
        found = kinematics.solutions(pose, TCP, GENERIC_Q)
        assert len(found) == 8
        names = [kinematics.configuration_of(s.q) for s in found]
        assert len(set(names)) == 8
        for solution, configuration in zip(found, names, strict=True):
            assert (configuration.shoulder == "left") == bool(solution.branch & SHOULDER)
            assert configuration_of(solution.q, dh) == configuration
            picked = kinematics.nearest_in(pose, GENERIC_Q, TCP, configuration._asdict())
            assert picked is not None
            assert np.allclose(picked, solution.q, atol=1e-9)
            for key, value in configuration._asdict().items():
                one = kinematics.nearest_in(pose, GENERIC_Q, TCP, {key: value})
                assert one is not None
                assert getattr(kinematics.configuration_of(one), key) == value


def _elbow_geometry(q: Vector) -> tuple[bool, float, float]:
    """From the UR10e chain's own joint positions, in the arm's vertical plane: whether the elbow
    (joint 3) lies above the line from the shoulder (joint 2) to joint 4, and the x (along joint 1's
    x axis) of joint 4 and of the wrist centre (joint 6's origin) relative to the shoulder."""
    points: list[tuple[float, float, float]] = []
    axes: list[tuple[float, float, float]] = []
    dh_chain(dh_joints(load_ur_model("ur10e").dh), q, axes, points)
    shoulder, elbow, wrist = np.array(points[1]), np.array(points[2]), np.array(points[3])
    x1 = np.array([math.cos(q[0]), math.sin(q[0]), 0.0])
    ex, ey = float((elbow - shoulder) @ x1), float(elbow[2] - shoulder[2])
    wx, wy = float((wrist - shoulder) @ x1), float(wrist[2] - shoulder[2])
    centre = float((np.array(points[5]) - shoulder) @ x1)
    return ey > wy / wx * ex, wx, centre


def test_configuration_names_by_the_joint_values() -> None:
    """UR's home pose is shoulder right, elbow up, wrist down; elbow names match the geometry."""
    from urdaemon.description.configurations import Configuration, configuration_of

    kinematics = UrKinematics(load_ur_model("ur10e"))
    home = (0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0)
    assert configuration_of(home) == Configuration("right", "up", "down")
    assert configuration_of((0.0, -1.2, 1.3, -1.0, 1.2 + 2 * math.pi, 0.0)).wrist == "up"
    rng = np.random.default_rng(11)
    checked = 0
    for _ in range(200):
        q = rng.uniform(-math.pi, math.pi, 6)
        above, wrist_x, centre_x = _elbow_geometry(q)
        assert (kinematics.configuration_of(q).shoulder == "right") == (centre_x < 0.0)
        if wrist_x * centre_x > 0.0:  # joint 4 and the wrist centre on one side: "above" is the name
            assert (kinematics.configuration_of(q).elbow == "up") == above
            checked += 1
    assert checked > 150
    # Reaching back over the base (wrist centre in front of joint 2 along x1): shoulder left.
    assert configuration_of((0.0, -math.pi / 2, -math.pi / 2, -math.pi / 2, 1.0, 0.0)).shoulder == "left"


def test_configuration_holds_along_a_motion_clear_of_singularities() -> None:
    """Joint 4 passing over the vertical above the shoulder (no singularity) keeps every name.

    Reproduction: the first definition named the elbow by joint 4's side of the shoulder, so this
    sound path flipped "up" to "down" midway (found by the linear planner's branch-flip check)."""
    kinematics = UrKinematics(load_ur_model("ur10e"))
    names = set()
    sides = set()
    for q2 in np.linspace(-1.95, -2.1, 16):
        q = (0.3, float(q2), 1.0, -math.pi / 2 - float(q2) - 1.0, 1.0, 0.2)
        assert singularity(kinematics.jacobian_rows(q)) > 0.03
        names.add(kinematics.configuration_of(q))
        sides.add(_elbow_geometry(q)[1] > 0.0)
    assert sides == {True, False}
    assert len(names) == 1


def test_nearest_in_refuses_a_configuration_the_pose_lacks() -> None:
    """A pose reachable only with the elbow stretched has no solution asked with an impossible key."""
    kinematics = UrKinematics(load_ur_model("ur5e"))
    pose = kinematics.forward(GENERIC_Q)
    assert kinematics.nearest_in(pose, GENERIC_Q, None, {"elbow": "sideways"}) is None
    assert kinematics.nearest_in(pose, GENERIC_Q, None, {}) == kinematics.nearest(pose, GENERIC_Q)


def test_singularity_name_says_which_is_nearest() -> None:
    """q5 = 0 is a wrist singularity, q3 = 0 an elbow one, the wrist centre over the base a shoulder one."""
    from urdaemon.description.configurations import singularity_name

    kinematics = UrKinematics(load_ur_model("ur10e"))
    assert kinematics.singularity_name((0.3, -1.2, 1.1, -0.4, 1e-4, 0.2)) == "wrist"
    assert kinematics.singularity_name((0.3, -1.2, 1e-4, -0.4, 1.0, 0.2)) == "elbow"
    # Wrist centre on joint 2's plane through the base axis: a2 c2 + a3 c23 + d5 s234 = 0.
    dh = load_ur_model("ur10e").dh
    q2, q3 = -1.17, -0.8
    planar = dh.a[1] * math.cos(q2) + dh.a[2] * math.cos(q2 + q3)
    q4 = math.asin(-planar / dh.d[4]) - (q2 + q3)
    shoulder = (0.3, q2, q3, q4, 1.0, 0.2)
    assert kinematics.singularity_name(shoulder) == "shoulder"
    assert singularity_name(shoulder) == "shoulder"
    assert float(np.linalg.svd(kinematics.jacobian(shoulder), compute_uv=False)[-1]) < 1e-3


def test_solving_loads_no_numpy() -> None:
    """The serve process solves poses and takes Jacobians without loading numpy (docs/kinematics.md).

    Reproduction: before issue 17 ik.py imported numpy at module level and solved with numpy."""
    probe = (
        "import sys\nfrom urdaemon.description import UrKinematics, load_ur_model\n"
        "k = UrKinematics(load_ur_model('ur5e'))\nq = (-1.23, -1.67, 1.42, 1.45, 1.51, -0.11)\n"
        "assert k.nearest(k.forward(q), q) is not None\nprint('numpy' in sys.modules)"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, check=True
    )
    assert done.stdout.strip() == "False"
