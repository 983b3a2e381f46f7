"""Calibration files, and the joint origins with UR's calibration correction."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from urdaemon.cell import ur_models
from urdaemon.description import DhParameters, joint_origins, load_calibration, load_ur_model, robot_dh
from urdaemon.description._transforms import rpy_of, xyz_rpy_matrix
from urdaemon.description.calibration import TOOL0_RPY, UrChain
from urdaemon.errors import ConfigError, DescriptionError

from .support import DATA, REAL_UR10E, dh_fk, make_cell, random_calibration, write_calibration

UR10E = load_ur_model("ur10e")


def _chain_fk(chain: UrChain, q: Any) -> np.ndarray:
    """base → tool0 through the URDF origins: Π origin_i·Rz(q_i), then flange and tool0."""
    t = np.eye(4)
    for origin, angle in zip(chain.joints, q, strict=True):
        c, s = math.cos(float(angle)), math.sin(float(angle))
        rz = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=float)
        t = t @ origin.matrix @ rz
    return t @ chain.flange.matrix @ xyz_rpy_matrix((0.0, 0.0, 0.0), TOOL0_RPY)


def _frame_positions(chain: UrChain) -> np.ndarray:
    """Where each joint frame and the flange sit in the base frame at q = 0."""
    t = np.eye(4)
    points = []
    for origin in (*chain.joints, chain.flange):
        t = t @ origin.matrix
        points.append(t[:3, 3].copy())
    return np.array(points)


# --- the file format ---------------------------------------------------------------------------


def test_absolute_dh_is_taken_as_is(tmp_path: Path) -> None:
    path = write_calibration(tmp_path / "cal.yaml", REAL_UR10E, model="ur10e", hash="calib_123")
    calibration = load_calibration(path, UR10E)
    assert calibration.dh == REAL_UR10E
    assert calibration.hash == "calib_123"
    assert calibration.source == str(path)


def test_delta_is_added_to_the_nominal(tmp_path: Path) -> None:
    path = write_calibration(tmp_path / "cal.yaml", REAL_UR10E, nominal=UR10E.dh)
    calibration = load_calibration(path, UR10E)
    assert calibration.hash is None
    for key in ("theta", "a", "d", "alpha"):
        np.testing.assert_allclose(getattr(calibration.dh, key), getattr(REAL_UR10E, key), rtol=0, atol=1e-12)


def test_zero_delta_gives_the_nominal(tmp_path: Path) -> None:
    path = write_calibration(tmp_path / "cal.yaml", UR10E.dh, nominal=UR10E.dh)
    assert load_calibration(path, UR10E).dh == UR10E.dh


def _good() -> dict[str, Any]:
    return {
        "model": "ur10e",
        "hash": "calib_42",
        "dh": {k: list(getattr(REAL_UR10E, k)) for k in ("theta", "a", "d", "alpha")},
    }


def _without(data: dict[str, Any], *path: str) -> dict[str, Any]:
    node = data
    for key in path[:-1]:
        node = node[key]
    del node[path[-1]]
    return data


def _with(data: dict[str, Any], value: Any, *path: str) -> dict[str, Any]:
    node = data
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return data


def _delta_and_dh() -> dict[str, Any]:
    data = _good()
    data["dh_delta"] = {k: [0.0] * 6 for k in ("theta", "a", "d", "alpha")}
    return data


@pytest.mark.parametrize(
    ("data", "key", "reason"),
    [
        (_with(_good(), 1, "extra"), "extra", "unknown key"),
        (_with(_good(), [1.0] * 5, "dh", "a"), "dh.a", "must have 6 values"),
        (_with(_good(), [0.0, 0.0, ".inf", 0.0, 0.0, 0.0], "dh", "d"), r"dh.d\[2\]", "must be a number"),
        (_with(_good(), [0.0, 0.0, float("inf"), 0.0, 0.0, 0.0], "dh", "d"), r"dh.d\[2\]", "must be finite"),
        (_with(_good(), [0.0, 0.0, 0.0, float("nan"), 0.0, 0.0], "dh", "theta"), r"dh.theta\[3\]", "finite"),
        (
            _with(_good(), [True, 0.0, 0.0, 0.0, 0.0, 0.0], "dh", "theta"),
            r"dh.theta\[0\]",
            "must be a number",
        ),
        (_without(_good(), "dh", "alpha"), "dh.alpha", "required key is missing"),
        (_with(_good(), 7, "dh", "beta"), "dh.beta", "unknown key"),
        (_with(_good(), "1 2 3", "dh", "a"), "dh.a", "must be a list"),
        (_without(_good(), "dh"), "dh", "found neither"),
        (_delta_and_dh(), "dh", "found both"),
        (_with(_good(), "ur5e", "model"), "model", "calibration is for 'ur5e' but the robot is a ur10e"),
        (_with(_good(), "5119701370761913513", "hash"), "hash", "calib_<digits>"),
        (_with(_good(), [0.0] * 6, "dh", "alpha"), r"dh.alpha\[0\]", "dh_delta written as dh"),
        (_with(_good(), [0.0] * 6, "dh"), "dh", "must be a mapping"),
    ],
)
def test_bad_calibration_names_file_and_key(
    tmp_path: Path, data: dict[str, Any], key: str, reason: str
) -> None:
    path = tmp_path / "cal.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    with pytest.raises(ConfigError, match=rf"cal\.yaml: {key}: .*{reason}"):
        load_calibration(path, UR10E)


def test_large_delta_alpha_is_suspicious(tmp_path: Path) -> None:
    deltas = {k: [0.0] * 6 for k in ("theta", "a", "d", "alpha")}
    deltas["alpha"][3] = 1.5707963267948966
    path = tmp_path / "cal.yaml"
    path.write_text(yaml.safe_dump({"dh_delta": deltas}), encoding="utf-8")
    with pytest.raises(ConfigError, match=r"cal\.yaml: dh_delta.alpha\[3\]: .*dh written as dh_delta"):
        load_calibration(path, UR10E)


@pytest.mark.parametrize(
    ("text", "reason"),
    [("", "the file is empty"), ("- 1\n- 2\n", "must be a mapping"), ("dh: [unclosed\n", "not valid YAML")],
)
def test_unreadable_calibration(tmp_path: Path, text: str, reason: str) -> None:
    path = tmp_path / "cal.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=rf"cal\.yaml.*{reason}"):
        load_calibration(path, UR10E)


def test_missing_calibration_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nothere\.yaml: cannot read calibration file"):
        load_calibration(tmp_path / "nothere.yaml", UR10E)


def test_robot_dh_uses_the_robots_calibration(tmp_path: Path) -> None:
    write_calibration(tmp_path / "alice.yaml", REAL_UR10E)
    cell = make_cell(
        tmp_path,
        {"name": "alice", "model": "ur10e", "calibration": "alice.yaml"},
        {"name": "bob", "model": "ur10e"},
    )
    assert robot_dh(cell.robot("alice")) == REAL_UR10E
    assert robot_dh(cell.robot("bob")) == UR10E.dh


def test_robot_dh_refuses_custom_robots(tmp_path: Path) -> None:
    cell = make_cell(
        tmp_path,
        {
            "name": "arm",
            "model": "custom",
            "description": {"xacro": str(DATA / "two_joint_arm.xacro"), "macro": "m"},
        },
    )
    with pytest.raises(DescriptionError, match="no DH parameters"):
        robot_dh(cell.robot("arm"))


# --- the joint origins -------------------------------------------------------------------------


@pytest.mark.parametrize("name", ur_models())
def test_correction_of_the_nominal_changes_nothing(name: str) -> None:
    dh = load_ur_model(name).dh
    corrected, plain = joint_origins(dh), joint_origins(dh, correct=False)
    for fixed, unfixed in zip(
        (*corrected.joints, corrected.flange), (*plain.joints, plain.flange), strict=True
    ):
        np.testing.assert_array_equal(fixed.matrix, unfixed.matrix)
        assert fixed.xyz == unfixed.xyz
        assert fixed.rpy == unfixed.rpy
    # and they are the plain DH ones: origin i = Tx(a[i-1])·Rx(alpha[i-1])·Tz(d[i])·Rz(theta[i])
    for i, origin in enumerate(corrected.joints):
        a, alpha = (dh.a[i - 1], dh.alpha[i - 1]) if i else (0.0, 0.0)
        expected_xyz = (a, -math.sin(alpha) * dh.d[i], math.cos(alpha) * dh.d[i])
        assert origin.xyz == pytest.approx(expected_xyz, abs=1e-15)
        assert origin.rpy == pytest.approx((alpha, 0.0, dh.theta[i]), abs=1e-15)


@pytest.mark.parametrize("seed", range(5))
def test_corrected_chain_keeps_the_dh_forward_kinematics(seed: int) -> None:
    rng = np.random.default_rng(seed)
    dh = REAL_UR10E if seed == 0 else random_calibration(load_ur_model(ur_models()[seed]).dh, rng)
    chain = joint_origins(dh)
    for _ in range(60):
        q = rng.uniform(-2 * math.pi, 2 * math.pi, 6)
        expected, actual = dh_fk(dh, q), _chain_fk(chain, q)
        np.testing.assert_allclose(actual[:3, 3], expected[:3, 3], rtol=0, atol=1e-9)
        np.testing.assert_allclose(actual[:3, :3], expected[:3, :3], rtol=0, atol=1e-9)


def test_correction_brings_a_real_calibration_home() -> None:
    # Uncorrected, the upper arm and forearm frames sit hundreds of metres away ...
    far = _frame_positions(joint_origins(REAL_UR10E, correct=False))
    assert np.linalg.norm(far, axis=1).max() > 400.0
    # ... corrected, every frame is within a few millimetres of the nominal UR10e's.
    near = _frame_positions(joint_origins(REAL_UR10E))
    nominal = _frame_positions(joint_origins(UR10E.dh))
    assert np.abs(near - nominal).max() < 5e-3
    assert np.linalg.norm(near, axis=1).max() < 2.0


def test_corrected_d2_and_d3_are_zero() -> None:
    chain = joint_origins(REAL_UR10E)
    # The origins of the elbow and wrist_1 joints lie in the plane of the joint before (z = 0 there).
    assert chain.joints[2].xyz[2] == pytest.approx(0.0, abs=1e-12)
    assert chain.joints[3].xyz[2] != pytest.approx(0.0, abs=1e-3)  # d4' keeps the wrist offset
    assert abs(chain.joints[3].xyz[2]) < 0.5


def test_parallel_axis_in_plane_is_refused() -> None:
    dh = UR10E.dh
    bad = DhParameters(theta=dh.theta, a=dh.a, d=dh.d, alpha=(dh.alpha[0], math.pi / 2, 0.0, *dh.alpha[3:]))
    with pytest.raises(DescriptionError, match="not UR kinematics"):
        joint_origins(bad)


# --- roll, pitch, yaw --------------------------------------------------------------------------


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    x, y, z, w = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w), 0],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w), 0],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y), 0],
            [0, 0, 0, 1],
        ]
    )


def test_rpy_rebuilds_random_rotations() -> None:
    rng = np.random.default_rng(7)
    for _ in range(500):
        m = _random_rotation(rng)
        rebuilt = xyz_rpy_matrix((0.0, 0.0, 0.0), rpy_of(m))
        np.testing.assert_allclose(rebuilt, m, rtol=0, atol=1e-14)


@pytest.mark.parametrize(
    "pitch", [math.pi / 2, -math.pi / 2, math.pi / 2 - 1e-9, -math.pi / 2 + 3e-12, 1.5707963]
)
def test_rpy_is_exact_near_gimbal_lock(pitch: float) -> None:
    rng = np.random.default_rng(11)
    for _ in range(50):
        roll, yaw = rng.uniform(-math.pi, math.pi, 2)
        m = xyz_rpy_matrix((0.0, 0.0, 0.0), (float(roll), pitch, float(yaw)))
        rpy = rpy_of(m)
        assert abs(rpy[1] - pitch) < 1e-7
        np.testing.assert_allclose(xyz_rpy_matrix((0.0, 0.0, 0.0), rpy), m, rtol=0, atol=1e-14)
