"""The URDF origins serve computes in plain floats equal the numpy maths they replaced (issue 15).

``joint_origins`` and the base inertial's turn by π were numpy 4x4 products, which made every serve
process load numpy (~12 MiB RSS) to build its URDF. The reference below is that numpy code as it
was, kept here as the oracle: on every config in configs/, on every UR model, and on calibrated
arms, the plain-float origins (``ur_params``, ``Origin.matrix``) agree with it to 1e-12.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from urdaemon.cell import load_cell, ur_models
from urdaemon.cell.robot_options import Robot
from urdaemon.description import DhParameters, joint_origins, load_calibration, load_ur_model, ur_params
from urdaemon.description.calibration import FLANGE_RPY
from urdaemon.description.urmodels import LinkInertial

from .support import REAL_UR10E, random_calibration

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = sorted((ROOT / "configs").glob("*.yaml"))
UR_ROBOTS = [(path.name, robot) for path in CONFIGS for robot in load_cell(path).robots if robot.is_ur]
"""Every UR robot of every shipped config (the custom servo arm has no DH origins to compare)."""
TOLERANCE = 1e-12

Matrix = NDArray[np.float64]


# --- the numpy reference: the code serve ran before issue 15 --------------------------------------


def _trans(x: float, z: float) -> Matrix:
    m = np.eye(4)
    m[0, 3], m[2, 3] = x, z
    return m


def _rot_x(angle: float) -> Matrix:
    c, s = math.cos(angle), math.sin(angle)
    m = np.eye(4)
    m[1, 1], m[1, 2], m[2, 1], m[2, 2] = c, -s, s, c
    return m


def _rot_z(angle: float) -> Matrix:
    c, s = math.cos(angle), math.sin(angle)
    m = np.eye(4)
    m[0, 0], m[0, 1], m[1, 0], m[1, 1] = c, -s, s, c
    return m


def _xyz_rpy(xyz: Any, rpy: Any) -> Matrix:
    roll, pitch, yaw = rpy
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    m = np.eye(4)
    m[0, :3] = (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr)
    m[1, :3] = (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr)
    m[2, :3] = (-sp, cp * sr, cp * cr)
    m[:3, 3] = xyz
    return m


def _rpy(m: Matrix) -> tuple[float, float, float]:
    yaw = math.atan2(m[1, 0], m[0, 0])
    cy, sy = math.cos(yaw), math.sin(yaw)
    pitch = math.atan2(-m[2, 0], cy * m[0, 0] + sy * m[1, 0])
    roll = math.atan2(sy * m[0, 2] - cy * m[1, 2], cy * m[1, 1] - sy * m[0, 1])
    return (float(roll) + 0.0, float(pitch) + 0.0, float(yaw) + 0.0)


def numpy_origins(dh: DhParameters) -> list[Matrix]:
    """The six joint origins and the flange, corrected, as the numpy code computed them."""
    theta, a, d, alpha = list(dh.theta), list(dh.a), list(dh.d), list(dh.alpha)
    passive = [_trans(a[i], 0.0) @ _rot_x(alpha[i]) for i in range(6)]
    for k in (1, 2):
        step = _trans(0.0, d[k]) @ _rot_z(theta[k]) @ passive[k]
        o, z = step[:3, 3], step[:3, 2]
        t = float(-o[2] / z[2])
        p = o + t * z
        new_theta = math.atan2(-float(p[1]), -float(p[0]))
        new_a = -math.hypot(float(p[0]), float(p[1]))
        passive[k] = _trans(new_a, 0.0) @ _rot_z(theta[k] - new_theta) @ _rot_x(alpha[k])
        d[k + 1] -= t
        theta[k], a[k], d[k] = new_theta, new_a, 0.0
    origins: list[Matrix] = []
    previous = np.eye(4)
    for i in range(6):
        origins.append(previous @ _trans(0.0, d[i]) @ _rot_z(theta[i]))
        previous = passive[i]
    origins.append(passive[5] @ _xyz_rpy((0.0, 0.0, 0.0), FLANGE_RPY))
    return origins


def numpy_inertial(data: LinkInertial, *, turn_pi: bool) -> tuple[Any, Any]:
    """(xyz, rpy) of a link's inertial origin as the numpy code wrote it."""
    if not turn_pi:
        return data.center_of_mass, data.center_of_mass_rpy
    m = _rot_z(-math.pi) @ _xyz_rpy(data.center_of_mass, data.center_of_mass_rpy)
    return (float(m[0, 3]) + 0.0, float(m[1, 3]) + 0.0, float(m[2, 3]) + 0.0), _rpy(m)


# --- the comparison ----------------------------------------------------------------------------


def _close(actual: Any, expected: Any, what: str) -> None:
    np.testing.assert_allclose(
        np.asarray(actual, dtype=float), expected, rtol=0, atol=TOLERANCE, err_msg=what
    )


def _assert_params_match(robot: Robot) -> None:
    model = load_ur_model(robot.model)
    dh = model.dh if robot.calibration is None else load_calibration(robot.calibration, model).dh
    params = ur_params(robot)
    expected = numpy_origins(dh)
    for joint, matrix in zip(model.joints, expected[:6], strict=True):
        spec = params["joints"][joint.name]
        _close(spec["xyz"], matrix[:3, 3], f"{robot.name} {joint.name} xyz")
        _close(spec["rpy"], _rpy(matrix), f"{robot.name} {joint.name} rpy")
    _close(params["flange"]["xyz"], expected[6][:3, 3], f"{robot.name} flange xyz")
    _close(params["flange"]["rpy"], _rpy(expected[6]), f"{robot.name} flange rpy")
    for link, inertial in model.links.items():
        name = "base_link_inertia" if link == "base_link" else link
        xyz, rpy = numpy_inertial(inertial, turn_pi=link == "base_link")
        _close(params["inertials"][name]["xyz"], xyz, f"{robot.name} {name} inertial xyz")
        _close(params["inertials"][name]["rpy"], rpy, f"{robot.name} {name} inertial rpy")


def _assert_chain_matches(dh: DhParameters) -> None:
    chain = joint_origins(dh)
    for i, (origin, matrix) in enumerate(zip((*chain.joints, chain.flange), numpy_origins(dh), strict=True)):
        _close(origin.matrix, matrix, f"origin {i} matrix")
        _close(origin.xyz, matrix[:3, 3], f"origin {i} xyz")
        _close(origin.rpy, _rpy(matrix), f"origin {i} rpy")


def test_the_shipped_configs_have_ur_robots_to_compare() -> None:
    assert len({config for config, _ in UR_ROBOTS}) >= 3


@pytest.mark.parametrize(("config", "robot"), UR_ROBOTS, ids=[f"{c}:{r.name}" for c, r in UR_ROBOTS])
def test_every_config_gets_the_numpy_origins(config: str, robot: Robot) -> None:
    _assert_params_match(robot)


@pytest.mark.parametrize("name", ur_models())
def test_every_model_gets_the_numpy_origins(name: str) -> None:
    _assert_chain_matches(load_ur_model(name).dh)


@pytest.mark.parametrize("seed", range(len(ur_models())))
def test_calibrated_arms_get_the_numpy_origins(seed: int) -> None:
    rng = np.random.default_rng(500 + seed)
    _assert_chain_matches(random_calibration(load_ur_model(ur_models()[seed]).dh, rng))
    _assert_chain_matches(REAL_UR10E)
