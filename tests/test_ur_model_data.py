"""Checks of the per-model Universal Robots data files in resources/ur/.

Every ``resources/ur/*.yaml`` is loaded with ``yaml.safe_load`` and checked against the schema that
urdaemon's loader expects, and against an independent reference table (UR's published nominal DH
parameters, joint limits and link masses) kept in this file.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any, NamedTuple

import pytest
import yaml

UR_DIR = Path(__file__).resolve().parents[1] / "resources" / "ur"

JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
LINKS = (
    "base_link",
    "shoulder_link",
    "upper_arm_link",
    "forearm_link",
    "wrist_1_link",
    "wrist_2_link",
    "wrist_3_link",
)
TOP_LEVEL_KEYS = (
    "model",
    "series",
    "robot_type",
    "control_rate_hz",
    "kinematics_hash",
    "dh",
    "joints",
    "links",
)
INERTIA_KEYS = ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")
RATE_KEYS = {"max_velocity", "max_effort", "max_acceleration", "max_jerk"}
CONTINUOUS_JOINT_KEYS = {"continuous"} | RATE_KEYS
LIMITED_JOINT_KEYS = {"min_position", "max_position"} | RATE_KEYS
HASH_RE = re.compile(r"calib_[0-9]+")
HALF_PI = math.pi / 2
DH_ALPHA = (HALF_PI, 0.0, 0.0, HALF_PI, -HALF_PI, 0.0)
TOL = 1e-12


class Ref(NamedTuple):
    """Independent reference values for one model."""

    series: str
    robot_type: int
    control_rate_hz: int
    d1: float
    a2: float
    a3: float
    d4: float
    d5: float
    d6: float
    kinematics_hash: str
    velocity_deg_s: tuple[float, ...]
    effort_nm: tuple[float, ...]
    position_deg: tuple[float | None, ...]  # None: continuous joint
    masses_kg: tuple[float, ...]  # base, shoulder, upper_arm, forearm, wrist_1, wrist_2, wrist_3
    max_acceleration: float  # urdaemon default, rad/s^2
    max_jerk: float  # urdaemon default, rad/s^3


_POS_FULL = (360.0, 360.0, 180.0, 360.0, 360.0, 360.0)
_POS_UR3 = (360.0, 360.0, 180.0, 360.0, 360.0, None)

REFERENCE: dict[str, Ref] = {
    "ur3": Ref(
        "cb3", 3, 125, 0.1519, -0.24365, -0.21325, 0.11235, 0.08535, 0.0819,
        "calib_9122066269688285636",
        (180, 180, 180, 360, 360, 360), (56, 56, 28, 12, 12, 12), _POS_UR3,
        (2.0, 2.0, 3.42, 1.26, 0.8, 0.8, 0.35), 5.0, 50.0,
    ),
    "ur3e": Ref(
        "e-series", 3, 500, 0.15185, -0.24355, -0.2132, 0.13105, 0.08535, 0.0921,
        "calib_16756443741236045476",
        (180, 180, 180, 360, 360, 360), (54, 54, 28, 9, 9, 9), _POS_UR3,
        (2.0, 1.98, 3.4445, 1.437, 0.871, 0.805, 0.261), 5.0, 50.0,
    ),
    "ur5": Ref(
        "cb3", 1, 125, 0.089159, -0.425, -0.39225, 0.10915, 0.09465, 0.0823,
        "calib_209549117540498681",
        (180,) * 6, (150, 150, 150, 28, 28, 28), _POS_FULL,
        (4.0, 3.7, 8.393, 2.33, 1.219, 1.219, 0.1879), 5.0, 50.0,
    ),
    "ur5e": Ref(
        "e-series", 1, 500, 0.1625, -0.425, -0.3922, 0.1333, 0.0997, 0.0996,
        "calib_12788084448423163542",
        (180,) * 6, (150, 150, 150, 28, 28, 28), _POS_FULL,
        (4.0, 3.761, 8.058, 2.846, 1.37, 1.3, 0.365), 5.0, 50.0,
    ),
    "ur10": Ref(
        "cb3", 2, 125, 0.1273, -0.612, -0.5723, 0.163941, 0.1157, 0.0922,
        "calib_17227329492635474227",
        (120, 120, 180, 180, 180, 180), (330, 330, 150, 56, 56, 56), _POS_FULL,
        (4.0, 7.1, 12.7, 4.27, 2.0, 2.0, 0.365), 5.0, 50.0,
    ),
    "ur10e": Ref(
        "e-series", 2, 500, 0.1807, -0.6127, -0.57155, 0.17415, 0.11985, 0.11655,
        "calib_5119701370761913513",
        (120, 120, 180, 180, 180, 180), (330, 330, 150, 54, 54, 54), _POS_FULL,
        (4.0, 7.369, 13.051, 3.989, 2.1, 1.98, 0.615), 5.0, 50.0,
    ),
    "ur16e": Ref(
        "e-series", 4, 500, 0.1807, -0.4784, -0.36, 0.17415, 0.11985, 0.11655,
        "calib_1935737212149401527",
        (120, 120, 180, 180, 180, 180), (330, 330, 150, 54, 54, 54), _POS_FULL,
        (4.0, 7.369, 10.45, 4.321, 2.18, 2.033, 0.907), 5.0, 50.0,
    ),
    "ur20": Ref(
        "ur-series", 7, 500, 0.2363, -0.862, -0.7287, 0.201, 0.1593, 0.1543,
        "calib_4890363623803256388",
        (120, 120, 150, 210, 210, 210), (738, 738, 433, 107, 107, 107), _POS_FULL,
        (4.0, 16.343, 29.632, 7.879, 3.054, 3.126, 0.926), 3.0, 30.0,
    ),
    "ur30": Ref(
        "ur-series", 8, 500, 0.2363, -0.637, -0.5037, 0.201, 0.1593, 0.1543,
        "calib_12001109639981648826",
        (120, 120, 150, 210, 210, 210), (738, 738, 433, 107, 107, 107), _POS_FULL,
        (4.0, 16.343, 28.542, 7.156, 3.054, 3.126, 0.926), 3.0, 30.0,
    ),
}  # fmt: skip

MODEL_FILES = sorted(UR_DIR.glob("*.yaml"))


def _load(path: Path) -> dict[str, Any]:
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    assert isinstance(data, dict), f"{path.name}: top level is not a mapping"
    return data


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _float_list(value: object, length: int, where: str) -> list[float]:
    assert isinstance(value, list), f"{where}: expected a list, got {value!r}"
    assert len(value) == length, f"{where}: expected {length} values, got {len(value)}"
    for item in value:
        assert isinstance(item, float), f"{where}: {item!r} is not a float"
        assert math.isfinite(item), f"{where}: {item!r} is not finite"
    return value


def _mapping(value: object, where: str) -> dict[str, Any]:
    assert isinstance(value, dict), f"{where}: expected a mapping, got {value!r}"
    return value


def test_every_reference_model_has_a_file() -> None:
    present = {path.stem for path in MODEL_FILES}
    missing = sorted(set(REFERENCE) - present)
    assert not missing, f"missing model files in {UR_DIR}: {missing}"


def test_every_file_has_a_reference_row() -> None:
    assert MODEL_FILES, f"no model files in {UR_DIR}"
    unknown = sorted(path.stem for path in MODEL_FILES if path.stem not in REFERENCE)
    assert not unknown, f"model files without a reference row in this test: {unknown}"


def test_readme_present() -> None:
    readme = UR_DIR / "README.md"
    assert readme.is_file()
    text = readme.read_text(encoding="utf-8")
    assert "Universal_Robots_ROS2_Description" in text
    assert "BSD-3-Clause" in text


@pytest.fixture(params=MODEL_FILES, ids=lambda path: path.stem)
def model_file(request: pytest.FixtureRequest) -> Path:
    path: Path = request.param
    return path


def test_top_level_schema(model_file: Path) -> None:
    data = _load(model_file)
    assert tuple(data) == TOP_LEVEL_KEYS, f"{model_file.name}: top-level keys {tuple(data)}"
    assert data["model"] == model_file.stem
    assert data["series"] in {"cb3", "e-series", "ur-series"}
    assert isinstance(data["robot_type"], int)
    assert not isinstance(data["robot_type"], bool)
    assert data["control_rate_hz"] in {125, 500}
    assert isinstance(data["kinematics_hash"], str)
    assert HASH_RE.fullmatch(data["kinematics_hash"]), data["kinematics_hash"]


def test_identity_matches_reference(model_file: Path) -> None:
    data = _load(model_file)
    ref = REFERENCE[model_file.stem]
    assert data["series"] == ref.series
    assert data["robot_type"] == ref.robot_type
    assert data["control_rate_hz"] == ref.control_rate_hz
    assert data["kinematics_hash"] == ref.kinematics_hash


def test_dh_parameters(model_file: Path) -> None:
    dh = _mapping(_load(model_file)["dh"], f"{model_file.name}: dh")
    assert tuple(dh) == ("theta", "a", "d", "alpha")
    theta = _float_list(dh["theta"], 6, "dh.theta")
    a = _float_list(dh["a"], 6, "dh.a")
    d = _float_list(dh["d"], 6, "dh.d")
    alpha = _float_list(dh["alpha"], 6, "dh.alpha")

    ref = REFERENCE[model_file.stem]
    assert theta == pytest.approx([0.0] * 6, abs=TOL)
    assert a == pytest.approx([0.0, ref.a2, ref.a3, 0.0, 0.0, 0.0], abs=TOL)
    assert d == pytest.approx([ref.d1, 0.0, 0.0, ref.d4, ref.d5, ref.d6], abs=TOL)
    assert alpha == pytest.approx(list(DH_ALPHA), abs=TOL)


def test_joint_limits(model_file: Path) -> None:
    joints = _mapping(_load(model_file)["joints"], f"{model_file.name}: joints")
    assert tuple(joints) == JOINTS
    ref = REFERENCE[model_file.stem]
    for index, name in enumerate(JOINTS):
        joint = _mapping(joints[name], f"{model_file.name}: {name}")
        where = f"{model_file.name}: {name}"
        position = ref.position_deg[index]
        if position is None:
            assert set(joint) == CONTINUOUS_JOINT_KEYS, where
            assert joint["continuous"] is True, where
        else:
            assert set(joint) == LIMITED_JOINT_KEYS, where
            for key in ("min_position", "max_position"):
                assert isinstance(joint[key], float), f"{where}: {key}"
            assert joint["min_position"] < 0.0 < joint["max_position"], where
            assert joint["max_position"] == pytest.approx(math.radians(position), abs=TOL), where
            assert joint["min_position"] == pytest.approx(-math.radians(position), abs=TOL), where
        for key in sorted(RATE_KEYS):
            value = joint[key]
            assert isinstance(value, float), f"{where}: {key} = {value!r} is not a float"
            assert math.isfinite(value), f"{where}: {key}"
            assert value > 0.0, f"{where}: {key} = {value} is not positive"
        assert joint["max_velocity"] == pytest.approx(math.radians(ref.velocity_deg_s[index]), abs=TOL), where
        assert joint["max_effort"] == pytest.approx(ref.effort_nm[index], abs=TOL), where
        assert joint["max_acceleration"] == ref.max_acceleration, where
        assert joint["max_jerk"] == ref.max_jerk, where


def test_links(model_file: Path) -> None:
    links = _mapping(_load(model_file)["links"], f"{model_file.name}: links")
    assert tuple(links) == LINKS
    ref = REFERENCE[model_file.stem]
    for index, name in enumerate(LINKS):
        where = f"{model_file.name}: {name}"
        link = _mapping(links[name], where)
        assert set(link) in (
            {"mass", "center_of_mass", "inertia"},
            {"mass", "center_of_mass", "center_of_mass_rpy", "inertia"},
        ), where
        assert isinstance(link["mass"], float), where
        assert link["mass"] > 0.0, where
        assert link["mass"] == pytest.approx(ref.masses_kg[index], abs=TOL), where
        _float_list(link["center_of_mass"], 3, f"{where}.center_of_mass")
        if "center_of_mass_rpy" in link:
            rpy = _float_list(link["center_of_mass_rpy"], 3, f"{where}.center_of_mass_rpy")
            assert any(angle != 0.0 for angle in rpy), f"{where}: omit an all-zero center_of_mass_rpy"
            assert all(abs(angle) <= math.pi for angle in rpy), where
        _check_inertia(link["inertia"], where)


def _check_inertia(value: object, where: str) -> None:
    if value is None:  # allowed by the schema when no inertia data is known
        return
    inertia = _mapping(value, f"{where}.inertia")
    assert tuple(inertia) == INERTIA_KEYS, where
    for key in INERTIA_KEYS:
        assert _is_number(inertia[key]), f"{where}: {key}"
        assert isinstance(inertia[key], float), f"{where}: {key} is not a float"
    ixx, iyy, izz = inertia["ixx"], inertia["iyy"], inertia["izz"]
    ixy, ixz, iyz = inertia["ixy"], inertia["ixz"], inertia["iyz"]
    for key in ("ixx", "iyy", "izz"):
        assert inertia[key] > 0.0, f"{where}: {key}"
    # A physical inertia tensor is positive definite (Sylvester) and obeys the triangle inequality.
    assert ixx * iyy - ixy * ixy > 0.0, where
    det = ixx * (iyy * izz - iyz * iyz) - ixy * (ixy * izz - iyz * ixz) + ixz * (ixy * iyz - iyy * ixz)
    assert det > 0.0, where
    assert ixx + iyy >= izz, where
    assert ixx + izz >= iyy, where
    assert iyy + izz >= ixx, where
