"""The cell URDF: UR arms (nominal and calibrated) match the DH kinematics; custom robots; errors."""

from __future__ import annotations

import math
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from urdaemon.cell import ur_models
from urdaemon.description import (
    DhParameters,
    build_cell_urdf,
    joint_origins,
    load_ur_model,
    load_urdf,
    robot_joint_names,
)
from urdaemon.errors import ConfigError, DescriptionError
from urdaemon.model import UR_JOINTS

from .support import DATA, REAL_UR10E, dh_fk, make_cell, random_calibration, write_calibration

MODELS = ur_models()
UR_LINKS = (
    "base_link",
    "base_link_inertia",
    "shoulder_link",
    "upper_arm_link",
    "forearm_link",
    "wrist_1_link",
    "wrist_2_link",
    "wrist_3_link",
    "flange",
    "tool0",
    "base",
)
TWO_JOINT = {"xacro": str(DATA / "two_joint_arm.xacro"), "macro": "two_joint_arm"}


def _assert_fk_matches(
    urdf: Any, prefix: str, dh: DhParameters, rng: np.random.Generator, count: int = 50
) -> None:
    names = [prefix + joint for joint in UR_JOINTS]
    for _ in range(count):
        q = rng.uniform(-2 * math.pi, 2 * math.pi, 6)
        urdf.update_cfg(dict(zip(names, q.tolist(), strict=True)))
        actual = urdf.get_transform(f"{prefix}tool0", f"{prefix}base")
        expected = dh_fk(dh, q)
        np.testing.assert_allclose(actual[:3, 3], expected[:3, 3], rtol=0, atol=1e-9)
        np.testing.assert_allclose(actual[:3, :3], expected[:3, :3], rtol=0, atol=1e-9)


def _assert_links_near_base(urdf: Any, prefix: str, reach: float = 2.0) -> None:
    urdf.update_cfg({prefix + joint: 0.0 for joint in UR_JOINTS})
    for link in UR_LINKS:
        distance = float(np.linalg.norm(urdf.get_transform(prefix + link, f"{prefix}base")[:3, 3]))
        assert distance < reach, f"{prefix}{link} is {distance:.1f} m from the base"


@pytest.mark.parametrize("name", MODELS)
@pytest.mark.parametrize("variant", ["nominal", "dh", "dh_delta"])
def test_tool0_in_base_equals_the_dh_forward_kinematics(tmp_path: Path, name: str, variant: str) -> None:
    rng = np.random.default_rng(1000 + 10 * MODELS.index(name) + ["nominal", "dh", "dh_delta"].index(variant))
    nominal = load_ur_model(name).dh
    robot: dict[str, Any] = {
        "name": "alice",
        "model": name,
        "pose": {"xyz": [0.3, -0.2, 0.1], "rpy": [0.1, 0.2, 0.3]},
    }
    dh = nominal
    if variant != "nominal":
        dh = random_calibration(nominal, rng)
        write_calibration(
            tmp_path / "cal.yaml", dh, nominal=nominal if variant == "dh_delta" else None, model=name
        )
        robot["calibration"] = "cal.yaml"
    urdf = load_urdf(build_cell_urdf(make_cell(tmp_path, robot)))
    _assert_fk_matches(urdf, "alice_", dh, rng)
    _assert_links_near_base(urdf, "alice_")


def test_a_real_calibration_builds_and_stays_near_the_base(tmp_path: Path) -> None:
    write_calibration(tmp_path / "cal.yaml", REAL_UR10E, hash="calib_1")
    cell = make_cell(tmp_path, {"name": "alice", "model": "ur10e", "calibration": "cal.yaml"})
    urdf = load_urdf(build_cell_urdf(cell))
    _assert_fk_matches(urdf, "alice_", REAL_UR10E, np.random.default_rng(3), count=60)
    _assert_links_near_base(urdf, "alice_", reach=1.5)


def test_pose_places_base_link_in_world(tmp_path: Path) -> None:
    cell = make_cell(
        tmp_path,
        {"name": "bob", "model": "ur5e", "pose": {"xyz": [1.0, 2.0, 3.0], "rpy": [0, 0, math.pi / 2]}},
    )
    urdf = load_urdf(build_cell_urdf(cell))
    t = urdf.get_transform("bob_base_link", "world")
    np.testing.assert_allclose(t[:3, 3], (1.0, 2.0, 3.0), atol=1e-15)
    np.testing.assert_allclose(t[:3, 0], (0.0, 1.0, 0.0), atol=1e-15)
    # the controller's base frame is turned by π about z from base_link
    base = urdf.get_transform("bob_base", "bob_base_link")
    np.testing.assert_allclose(base[:3, :3], np.diag([-1.0, -1.0, 1.0]), atol=1e-15)


def test_structure_of_a_ur_arm(tmp_path: Path) -> None:
    text = build_cell_urdf(make_cell(tmp_path, {"name": "alice", "model": "ur3e"}, name="my-cell"))
    root = ET.fromstring(text)
    assert root.get("name") == "my-cell"
    links = {link.get("name") for link in root.iter("link")}
    assert links == {"world"} | {f"alice_{link}" for link in UR_LINKS}
    joints = {j.get("name"): j for j in root.iter("joint")}
    kinds = {name: j.get("type") for name, j in joints.items()}
    assert [kinds[f"alice_{j}"] for j in UR_JOINTS] == ["revolute"] * 5 + ["continuous"]
    assert sum(kind == "fixed" for kind in kinds.values()) == 5
    mount = joints["alice_base_link_parent_joint"].find("parent")
    assert mount is not None
    assert mount.get("link") == "world"
    for joint in UR_JOINTS:
        axis = joints[f"alice_{joint}"].find("axis")
        assert axis is not None
        assert axis.get("xyz") == "0 0 1"
    wrist_3 = joints["alice_wrist_3_joint"].find("limit")
    assert wrist_3 is not None
    assert wrist_3.get("lower") is None
    assert float(wrist_3.get("velocity", "0")) > 0
    # inertials everywhere there is data; the base's sits on base_link_inertia, like UR's own
    inertial_links = {link.get("name") for link in root.iter("link") if link.find("inertial") is not None}
    assert inertial_links == {f"alice_{n}" for n in UR_LINKS[1:8]}


def test_origins_are_written_at_full_precision(tmp_path: Path) -> None:
    write_calibration(tmp_path / "cal.yaml", REAL_UR10E)
    root = ET.fromstring(
        build_cell_urdf(make_cell(tmp_path, {"name": "a", "model": "ur10e", "calibration": "cal.yaml"}))
    )
    chain = joint_origins(REAL_UR10E)
    for joint, expected in zip(UR_JOINTS, chain.joints, strict=True):
        element = next(j for j in root.iter("joint") if j.get("name") == f"a_{joint}")
        origin = element.find("origin")
        assert origin is not None
        assert tuple(float(v) for v in origin.get("xyz", "").split()) == expected.xyz
        assert tuple(float(v) for v in origin.get("rpy", "").split()) == expected.rpy


def test_output_is_deterministic(tmp_path: Path) -> None:
    cell = make_cell(
        tmp_path,
        {"name": "alice", "model": "ur10e"},
        {"name": "arm", "model": "custom", "description": TWO_JOINT},
    )
    first, second = build_cell_urdf(cell), build_cell_urdf(cell)
    assert first == second
    assert "/tmp" not in first
    assert "autogenerated" not in first


def test_limit_overrides_go_into_the_urdf(tmp_path: Path) -> None:
    cell = make_cell(
        tmp_path,
        {
            "name": "alice",
            "model": "ur3e",
            "joint_limits": {
                "elbow_joint": {"min_position": -2.5, "max_velocity": 1.25, "max_acceleration": 2.0},
                "wrist_3_joint": {"min_position": -4.0, "max_position": 4.0},
            },
        },
    )
    root = ET.fromstring(build_cell_urdf(cell))
    joints = {j.get("name"): j for j in root.iter("joint")}
    elbow = joints["alice_elbow_joint"].find("limit")
    assert elbow is not None
    assert (elbow.get("lower"), elbow.get("upper"), elbow.get("velocity")) == ("-2.5", repr(math.pi), "1.25")
    # limiting a continuous joint makes it revolute
    assert joints["alice_wrist_3_joint"].get("type") == "revolute"
    wrist = joints["alice_wrist_3_joint"].find("limit")
    assert wrist is not None
    assert (wrist.get("lower"), wrist.get("upper")) == ("-4.0", "4.0")


def test_one_sided_limit_on_a_continuous_joint_is_refused(tmp_path: Path) -> None:
    cell = make_cell(
        tmp_path, {"name": "alice", "model": "ur3", "joint_limits": {"wrist_3_joint": {"max_position": 1.0}}}
    )
    with pytest.raises(
        DescriptionError, match=r"robot 'alice': joint_limits.wrist_3_joint: the joint is continuous"
    ):
        build_cell_urdf(cell)


def test_override_must_keep_min_below_max(tmp_path: Path) -> None:
    cell = make_cell(
        tmp_path, {"name": "alice", "model": "ur10e", "joint_limits": {"elbow_joint": {"min_position": 3.5}}}
    )
    with pytest.raises(
        DescriptionError, match=r"robot 'alice': joint_limits.elbow_joint: min_position 3.5 must be below"
    ):
        build_cell_urdf(cell)


def test_two_ur_arms_and_a_custom_arm_on_a_tool(tmp_path: Path) -> None:
    cell = make_cell(
        tmp_path,
        {"name": "alice", "model": "ur10e", "pose": {"xyz": [0.5, 0, 0]}},
        {"name": "bob", "model": "ur3e", "pose": {"xyz": [-0.5, 0, 0], "rpy": [0, 0, math.pi]}},
        {
            "name": "arm",
            "model": "custom",
            "description": TWO_JOINT,
            "pose": {"parent": "alice_tool0", "xyz": [0, 0, 0.05]},
        },
    )
    urdf = load_urdf(build_cell_urdf(cell))
    assert robot_joint_names(cell.robot("arm"), urdf) == ("arm_yaw", "arm_reach")
    assert robot_joint_names(cell.robot("bob"), urdf) == tuple(f"bob_{j}" for j in UR_JOINTS)
    urdf.update_cfg(dict.fromkeys(urdf.actuated_joint_names, 0.0))
    on_tool = urdf.get_transform("arm_base_link", "alice_tool0")
    np.testing.assert_allclose(on_tool[:3, 3], (0.0, 0.0, 0.05), atol=1e-15)
    _assert_fk_matches(urdf, "bob_", load_ur_model("ur3e").dh, np.random.default_rng(5), count=20)


def test_custom_joint_names_skip_a_neighbour_with_a_longer_prefix(tmp_path: Path) -> None:
    cell = make_cell(
        tmp_path,
        {"name": "arm", "model": "custom", "description": TWO_JOINT},
        {"name": "arm_2", "model": "custom", "description": TWO_JOINT, "pose": {"xyz": [1, 0, 0]}},
    )
    urdf = load_urdf(build_cell_urdf(cell))
    assert robot_joint_names(cell.robot("arm"), urdf) == ("arm_yaw", "arm_reach")
    assert robot_joint_names(cell.robot("arm_2"), urdf) == ("arm_2_yaw", "arm_2_reach")


def test_paths_with_dollars_are_taken_literally(tmp_path: Path) -> None:
    odd = tmp_path / "we$(ird) ${dir}"
    odd.mkdir()
    shutil.copy(DATA / "two_joint_arm.xacro", odd / "arm.xacro")
    write_calibration(odd / "cal.yaml", REAL_UR10E)
    cell = make_cell(
        odd,
        {"name": "arm", "model": "custom", "description": {"xacro": "arm.xacro", "macro": "two_joint_arm"}},
        {"name": "alice", "model": "ur10e", "calibration": "cal.yaml"},
    )
    assert 'name="arm_yaw"' in build_cell_urdf(cell)


def test_missing_macro_names_the_robot(tmp_path: Path) -> None:
    cell = make_cell(
        tmp_path,
        {"name": "alice", "model": "ur10e"},
        {"name": "arm", "model": "custom", "description": {**TWO_JOINT, "macro": "no_such_arm"}},
    )
    with pytest.raises(
        DescriptionError, match=r"robot 'arm': xacro failed: .*unknown macro name: xacro:no_such_arm"
    ):
        build_cell_urdf(cell)


def test_broken_xacro_names_the_robot(tmp_path: Path) -> None:
    cell = make_cell(
        tmp_path,
        {"name": "alice", "model": "ur10e"},
        {
            "name": "wreck",
            "model": "custom",
            "description": {"xacro": str(DATA / "broken.xacro"), "macro": "broken_arm"},
        },
    )
    with pytest.raises(DescriptionError, match=r"robot 'wreck': xacro failed: .*mismatched tag"):
        build_cell_urdf(cell)


def test_bad_calibration_names_the_robot(tmp_path: Path) -> None:
    (tmp_path / "cal.yaml").write_text("dh_delta: {theta: [0, 0]}\n", encoding="utf-8")
    cell = make_cell(tmp_path, {"name": "alice", "model": "ur10e", "calibration": "cal.yaml"})
    with pytest.raises(
        DescriptionError, match=r"robot 'alice': .*cal\.yaml: dh_delta.a: required key"
    ) as caught:
        build_cell_urdf(cell)
    assert isinstance(caught.value.__cause__, ConfigError)


def test_unknown_parent_link_names_the_robot(tmp_path: Path) -> None:
    cell = make_cell(
        tmp_path,
        {"name": "alice", "model": "ur10e"},
        {"name": "bob", "model": "ur5e", "pose": {"parent": "alice_nowhere"}},
    )
    with pytest.raises(
        DescriptionError,
        match=r"'bob_base_link_parent_joint' \(robot 'bob'\): parent link 'alice_nowhere' does not exist",
    ):
        build_cell_urdf(cell)


def test_unprefixed_links_of_two_robots_clash(tmp_path: Path) -> None:
    description = {"xacro": str(DATA / "unprefixed.xacro"), "macro": "unprefixed_arm"}
    cell = make_cell(
        tmp_path,
        {"name": "one", "model": "custom", "description": description},
        {"name": "two", "model": "custom", "description": description, "pose": {"xyz": [1, 0, 0]}},
    )
    with pytest.raises(DescriptionError, match=r"link 'gadget' is defined twice \(no robot"):
        build_cell_urdf(cell)


def test_custom_tool_link_must_exist(tmp_path: Path) -> None:
    cell = make_cell(
        tmp_path, {"name": "arm", "model": "custom", "description": {**TWO_JOINT, "tool_link": "gripper"}}
    )
    with pytest.raises(DescriptionError, match=r"robot 'arm': its description has no link 'arm_gripper'"):
        build_cell_urdf(cell)


def test_custom_override_for_an_unknown_joint(tmp_path: Path) -> None:
    cell = make_cell(
        tmp_path,
        {
            "name": "arm",
            "model": "custom",
            "description": TWO_JOINT,
            "joint_limits": {"pitch": {"max_velocity": 1.0}},
        },
    )
    with pytest.raises(
        DescriptionError, match=r"robot 'arm': joint_limits.pitch: its description has no joint 'arm_pitch'"
    ):
        build_cell_urdf(cell)
