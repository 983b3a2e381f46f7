"""The arm's dynamics (description/dynamics.py) against an independent Newton–Euler written here.

The reference is built from the same published facts (the model data's link inertials) but not from
the module's code: its link frames come from the URDF joint origins of UR's ROS 2 description as
that description's macro writes them (shoulder at z = d1, upper arm turned by roll π/2, forearm at
x = a2, wrist 1 at (a3, 0, d4), wrist 2 at (0, −d5, 0) turned by roll π/2, wrist 3 at (0, d6, 0)
turned by rpy (π/2, π, π); flange and tool0 turned by (0, −π/2, −π/2) and (π/2, 0, π/2)), with numpy,
and the recursion runs in each link's own frame (Craig's outward/inward Newton–Euler). The mass
matrix's columns are RNEA(q, 0, e_i) without gravity.

Reproduction on the code before issue 33: ``urdaemon.description.dynamics`` did not exist.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from urdaemon.description.dynamics import ArmDynamics, Payload
from urdaemon.description.kinematics import DhKinematics
from urdaemon.description.urmodels import UR_LINKS, load_ur_model

MODELS = ("ur3", "ur3e", "ur5", "ur5e", "ur10", "ur10e", "ur16e", "ur20", "ur30")
GRAVITY = (0.0, 0.0, 9.82)
PAYLOAD = Payload.of(3.2, (0.02, -0.01, 0.07), (0.012, 0.015, 0.009, 0.001, -0.0005, 0.0002))

angles = st.lists(st.floats(-math.pi, math.pi), min_size=6, max_size=6)
speeds = st.lists(st.floats(-2.0, 2.0), min_size=6, max_size=6)


def _rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (
        math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw),
    )  # fmt: skip
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    result: np.ndarray = rz @ ry @ rx
    return result


class Reference:
    """Newton–Euler in link frames, from the ROS description's joint origins of a nominal model."""

    def __init__(self, name: str, payload: Payload | None = None) -> None:
        model = load_ur_model(name)
        a, d = model.dh.a, model.dh.d
        half = math.pi / 2
        # parent link -> joint frame (translation, rotation), as ur_macro.xacro writes them
        self.joints = [
            (np.array([0.0, 0.0, d[0]]), _rpy(0, 0, 0)),
            (np.zeros(3), _rpy(half, 0, 0)),
            (np.array([a[1], 0.0, 0.0]), _rpy(0, 0, 0)),
            (np.array([a[2], 0.0, d[3]]), _rpy(0, 0, 0)),
            (np.array([0.0, -d[4], 0.0]), _rpy(half, 0, 0)),
            (np.array([0.0, d[5], 0.0]), _rpy(half, math.pi, math.pi)),
        ]
        self.tool0 = _rpy(0, -half, -half) @ _rpy(half, 0, half)
        self.bodies = []
        for link in UR_LINKS[1:]:
            inertial = model.links[link]
            assert inertial.inertia is not None
            ixx, iyy, izz, ixy, ixz, iyz = inertial.inertia
            tensor = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
            turn = _rpy(*inertial.center_of_mass_rpy)
            self.bodies.append([inertial.mass, np.array(inertial.center_of_mass), turn @ tensor @ turn.T])
        if payload is not None:
            self._add(payload)

    def _add(self, payload: Payload) -> None:
        """A payload as a second rigid body on wrist_3_link (kept as its own term, not merged)."""
        ixx, iyy, izz, ixy, ixz, iyz = payload.inertia
        tensor = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        self.payload = (payload.mass, self.tool0 @ np.array(payload.cog), self.tool0 @ tensor @ self.tool0.T)

    payload: tuple[float, np.ndarray, np.ndarray] | None = None

    def rnea(
        self, q: Sequence[float], qd: Sequence[float], qdd: Sequence[float], g: Sequence[float]
    ) -> np.ndarray:
        z = np.array([0.0, 0.0, 1.0])
        w, dw, dv = np.zeros(3), np.zeros(3), np.array(g, dtype=float)
        kept = []
        for i, (p, r0) in enumerate(self.joints):
            c, s = math.cos(q[i]), math.sin(q[i])
            r = r0 @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])  # parent -> link i+1
            rt = r.T
            dv = rt @ (dv + np.cross(dw, p) + np.cross(w, np.cross(w, p)))
            dw = rt @ dw + np.cross(rt @ w, z * qd[i]) + z * qdd[i]
            w = rt @ w + z * qd[i]
            terms = [self.bodies[i]] + ([list(self.payload)] if i == 5 and self.payload else [])
            force, moment = np.zeros(3), np.zeros(3)
            for mass, com, tensor in terms:
                f = mass * (dv + np.cross(dw, com) + np.cross(w, np.cross(w, com)))
                force += f
                moment += tensor @ dw + np.cross(w, tensor @ w) + np.cross(com, f)
            kept.append((r, p, force, moment))
        tau = np.zeros(6)
        f_out, n_out = np.zeros(3), np.zeros(3)
        for i in range(5, -1, -1):
            r, p, force, moment = kept[i]
            if i < 5:
                r_next, p_next = kept[i + 1][0], kept[i + 1][1]
                f_child, n_child = r_next @ f_out, r_next @ n_out + np.cross(p_next, r_next @ f_out)
            else:
                f_child, n_child = np.zeros(3), np.zeros(3)
            f_out, n_out = force + f_child, moment + n_child
            tau[i] = n_out[2]
        return tau

    def mass_matrix(self, q: Sequence[float]) -> np.ndarray:
        return np.array([self.rnea(q, [0.0] * 6, list(e), (0, 0, 0)) for e in np.eye(6)]).T


@pytest.mark.parametrize("name", MODELS)
@settings(max_examples=15, deadline=None)
@given(q=angles)
def test_the_mass_matrix_is_symmetric_positive_definite_and_matches_newton_euler(
    name: str, q: list[float]
) -> None:
    for payload in (None, PAYLOAD):
        model = load_ur_model(name)
        m = np.array(ArmDynamics(model, model.dh).mass_matrix(q, payload))
        assert np.array_equal(m, m.T)
        assert np.linalg.eigvalsh(m).min() > 0.0
        reference = Reference(name, payload).mass_matrix(q)
        assert np.abs(m - reference).max() <= 1e-9, np.abs(m - reference).max()


@pytest.mark.parametrize("name", MODELS)
@settings(max_examples=10, deadline=None)
@given(q=angles, qd=speeds, qdd=speeds)
def test_inverse_coriolis_and_gravity_torques_match_newton_euler(
    name: str, q: list[float], qd: list[float], qdd: list[float]
) -> None:
    model = load_ur_model(name)
    dynamics = ArmDynamics(model, model.dh)
    reference = Reference(name, PAYLOAD)
    tau = dynamics.inverse_dynamics(q, qd, qdd, GRAVITY, PAYLOAD)
    assert np.abs(np.array(tau) - reference.rnea(q, qd, qdd, GRAVITY)).max() <= 1e-9
    coriolis = dynamics.coriolis(q, qd, PAYLOAD)
    assert np.abs(np.array(coriolis) - reference.rnea(q, qd, [0.0] * 6, (0, 0, 0))).max() <= 1e-9
    gravity = dynamics.gravity_torques(q, GRAVITY, PAYLOAD)
    assert np.abs(np.array(gravity) - reference.rnea(q, [0.0] * 6, [0.0] * 6, GRAVITY)).max() <= 1e-9
    # forward dynamics inverts inverse dynamics
    back = dynamics.forward_dynamics(q, qd, tau, GRAVITY, PAYLOAD)
    assert np.abs(np.array(back) - np.array(qdd)).max() <= 1e-8


@pytest.mark.parametrize("name", MODELS)
def test_the_link_frames_carry_tool0_where_the_dh_kinematics_put_it(name: str) -> None:
    model = load_ur_model(name)
    q = [0.4, -1.1, 1.3, -0.6, 0.8, -0.2]
    tool0 = ArmDynamics(model, model.dh).tool0(q)
    assert list(tool0[9:]) == pytest.approx(DhKinematics(model.dh).tool_pose(q)[:3], abs=1e-12)


@settings(max_examples=20, deadline=None)
@given(q=angles, qd=speeds)
def test_the_jacobian_derivative_is_the_jacobians_rate_along_the_joint_speeds(
    q: list[float], qd: list[float]
) -> None:
    model = load_ur_model("ur10e")
    dynamics = ArmDynamics(model, model.dh)
    tcp = (0.01, -0.02, 0.12, 0.1, 0.0, 0.3)
    h = 1e-6
    ahead = np.array(dynamics.jacobian([a + h * b for a, b in zip(q, qd, strict=True)], tcp))
    behind = np.array(dynamics.jacobian([a - h * b for a, b in zip(q, qd, strict=True)], tcp))
    rate = np.array(dynamics.jacobian_derivative(q, qd, tcp))
    assert np.abs(rate - (ahead - behind) / (2 * h)).max() <= 1e-6


def test_a_payload_with_no_mass_changes_nothing() -> None:
    model = load_ur_model("ur5e")
    dynamics = ArmDynamics(model, model.dh)
    q = [0.1, -1.0, 1.2, -0.3, 0.4, 0.5]
    assert dynamics.mass_matrix(q, Payload()) == dynamics.mass_matrix(q)
