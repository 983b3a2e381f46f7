"""The UR model data loader: every shipped model loads; broken files name the file and the key."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
import yaml

from urdaemon.cell import ur_models
from urdaemon.description import load_ur_model, load_ur_model_file
from urdaemon.description.urmodels import UR_LINKS
from urdaemon.errors import DescriptionError
from urdaemon.model import UR_JOINTS
from urdaemon.paths import resource_path

MODELS = ur_models()


def test_all_nine_models_ship() -> None:
    assert set(MODELS) == {"ur3", "ur3e", "ur5", "ur5e", "ur10", "ur10e", "ur16e", "ur20", "ur30"}


@pytest.mark.parametrize("name", MODELS)
def test_every_model_loads_complete(name: str) -> None:
    model = load_ur_model(name)
    assert model.model == name
    assert tuple(j.name for j in model.joints) == UR_JOINTS
    assert tuple(model.links) == UR_LINKS
    half_pi = math.pi / 2
    assert model.dh.alpha == (half_pi, 0.0, 0.0, half_pi, -half_pi, 0.0)
    assert model.dh.d[0] > 0.0
    assert model.dh.a[1] < 0.0
    assert model.dh.a[2] < 0.0
    assert model.control_rate_hz == (125.0 if model.series == "cb3" else 500.0)
    assert model.kinematics_hash.startswith("calib_")
    for joint in model.joints:
        assert joint.max_velocity > 0.0
        assert joint.max_acceleration > 0.0
        assert joint.max_jerk > 0.0
        if joint.continuous:
            assert joint.min_position is None
            assert joint.max_position is None
        else:
            assert joint.min_position is not None
            assert joint.max_position is not None
            assert joint.min_position < joint.max_position
    # only the ur3 wrists turn endlessly
    continuous = [j.name for j in model.joints if j.continuous]
    assert continuous == (["wrist_3_joint"] if name in ("ur3", "ur3e") else [])
    assert all(link.mass > 0.0 for link in model.links.values())


def test_known_values_of_the_ur10e() -> None:
    model = load_ur_model("ur10e")
    assert model.dh.a == (0.0, -0.6127, -0.57155, 0.0, 0.0, 0.0)
    assert model.dh.d == (0.1807, 0.0, 0.0, 0.17415, 0.11985, 0.11655)
    assert model.robot_type == 2
    assert model.joint("elbow_joint").max_position == math.pi
    shoulder = model.links["shoulder_link"]
    assert shoulder.center_of_mass_rpy == (math.pi / 2, 0.0, 0.0)
    # inertia order is the data file's: ixx, iyy, izz, ixy, ixz, iyz
    assert shoulder.inertia == (0.03408, 0.03529, 0.02156, 2.0e-05, -0.00425, 8.0e-05)


def test_models_are_cached_and_read_only() -> None:
    assert load_ur_model("ur5e") is load_ur_model("ur5e")
    links: Any = load_ur_model("ur5e").links
    with pytest.raises(TypeError):
        links["base_link"] = None


def test_unknown_model_names_the_missing_file() -> None:
    with pytest.raises(DescriptionError, match=r"ur99\.yaml"):
        load_ur_model("ur99")


def test_model_name_cannot_leave_the_resources_folder() -> None:
    with pytest.raises(DescriptionError, match="invalid UR model name"):
        load_ur_model("../ur/ur10e")


def _base() -> dict[str, Any]:
    data = yaml.safe_load(resource_path("ur", "ur10e.yaml").read_text(encoding="utf-8"))
    assert isinstance(data, dict)
    return data


def _set(data: dict[str, Any], path: str, value: Any) -> None:
    *parents, last = path.split(".")
    node = data
    for key in parents:
        node = node[key]
    if value is _DELETE:
        del node[last]
    else:
        node[last] = value


_DELETE = object()


@pytest.mark.parametrize(
    ("path", "value", "key", "reason"),
    [
        ("dh.a", [0.0, 1.0], "dh.a", "must have 6 values"),
        ("dh.d", [0.1, 0.0, 0.0, float("nan"), 0.0, 0.0], r"dh.d\[3\]", "finite"),
        ("dh.theta", _DELETE, "dh.theta", "required key is missing"),
        ("extra", 1, "extra", "unknown key"),
        ("joints.elbow_joint.max_velocity", True, "joints.elbow_joint.max_velocity", "must be a number"),
        ("joints.elbow_joint.max_velocity", -1.0, "joints.elbow_joint.max_velocity", "must be positive"),
        ("joints.elbow_joint.min_position", 4.0, "joints.elbow_joint.min_position", "must be below"),
        ("joints.wrist_3_joint.continuous", "yes", "joints.wrist_3_joint.continuous", "true or false"),
        ("links.wrist_3_link", _DELETE, "links.wrist_3_link", "required key is missing"),
        ("links.forearm_link.inertia.ixx", "big", "links.forearm_link.inertia.ixx", "must be a number"),
        ("links.forearm_link.center_of_mass", [0.0, 0.0], "links.forearm_link.center_of_mass", "3 values"),
        ("kinematics_hash", "5119701370761913513", "kinematics_hash", "calib_"),
        ("series", "f-series", "series", "must be one of"),
        ("model", "ur5e", "model", "file is for 'ur10e'"),
    ],
)
def test_broken_model_file_names_file_and_key(
    tmp_path: Path, path: str, value: Any, key: str, reason: str
) -> None:
    data = _base()
    _set(data, path, value)
    bad = tmp_path / "ur10e.yaml"
    bad.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    with pytest.raises(DescriptionError, match=rf"ur10e\.yaml: {key}: .*{reason}"):
        load_ur_model_file(bad, expected_model="ur10e")


def test_joints_out_of_order_are_rejected(tmp_path: Path) -> None:
    data = _base()
    joints = data["joints"]
    data["joints"] = {name: joints[name] for name in reversed(list(joints))}
    bad = tmp_path / "flipped.yaml"
    bad.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    with pytest.raises(DescriptionError, match=r"flipped\.yaml: joints: must list exactly"):
        load_ur_model_file(bad)


def test_null_inertia_is_allowed(tmp_path: Path) -> None:
    data = _base()
    data["links"]["wrist_3_link"]["inertia"] = None
    path = tmp_path / "ur10e.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    assert load_ur_model_file(path).links["wrist_3_link"].inertia is None


def test_not_yaml_is_a_description_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("model: [unclosed\n", encoding="utf-8")
    with pytest.raises(DescriptionError, match=r"bad\.yaml: not valid YAML"):
        load_ur_model_file(bad)
