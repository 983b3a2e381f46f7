"""The UR links' shapes in the cell URDF: present, joined up through the joints, sized by model.

Reproduction: before the shapes, every UR link of the cell URDF was empty (inertials only), so a
viewer (RViz, Foxglove, viser through yourdfpy) showed frames and nothing else. Each test here
loads the built URDF as a viewer would (yourdfpy with its scene graph and meshes) or reads its XML.
"""

from __future__ import annotations

import io
import math
import xml.etree.ElementTree as ET
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yourdfpy

from urdaemon.cell import ur_models
from urdaemon.description import build_cell_urdf, load_ur_model
from urdaemon.description.urdf_facts import read_urdf_facts
from urdaemon.model import UR_JOINTS

from .support import REAL_UR10E, make_cell, random_calibration, write_calibration

MODELS = ur_models()
DRAWN_LINKS = (
    "base_link_inertia",
    "shoulder_link",
    "upper_arm_link",
    "forearm_link",
    "wrist_1_link",
    "wrist_2_link",
    "wrist_3_link",
)
# link -> the link whose origin its tube ends on
TUBES = {
    "upper_arm_link": "forearm_link",
    "forearm_link": "wrist_1_link",
    "wrist_1_link": "wrist_2_link",
    "wrist_2_link": "wrist_3_link",
}


def _viewer_load(text: str) -> Any:
    """The URDF as a viewer loads it: scene graph with every visual built as a mesh."""
    return yourdfpy.URDF.load(io.StringIO(text), build_scene_graph=True, load_meshes=True)


def _cylinder_ends(urdf: Any, visual: str) -> tuple[Any, Any]:
    """World (root link) positions of the -z and +z end of the cylinder visual named ``visual``."""
    scene = urdf.scene
    matches = [node for node in scene.graph.nodes_geometry if scene.graph[node][1] == visual]
    assert len(matches) == 1, f"{visual}: {len(matches)} scene nodes"
    transform, geometry = scene.graph[matches[0]]
    half = scene.geometry[geometry].primitive.height / 2
    low = transform @ np.array([0.0, 0.0, -half, 1.0])
    high = transform @ np.array([0.0, 0.0, half, 1.0])
    return low[:3], high[:3]


def _origin_of(urdf: Any, link: str) -> Any:
    return urdf.get_transform(link, urdf.base_link)[:3, 3]


def _random_pose(urdf: Any, prefix: str, rng: np.random.Generator) -> None:
    q = rng.uniform(-math.pi, math.pi, 6)
    urdf.update_cfg(dict(zip([prefix + j for j in UR_JOINTS], q.tolist(), strict=True)))


def _assert_joined_up(urdf: Any, prefix: str, rng: np.random.Generator, poses: int = 5) -> None:
    """Each tube ends on its child joint's origin, the base meets the shoulder, the disc the flange."""
    for _ in range(poses):
        _random_pose(urdf, prefix, rng)
        for link, child in TUBES.items():
            _, end = _cylinder_ends(urdf, f"{prefix}{link}_tube")
            np.testing.assert_allclose(end, _origin_of(urdf, prefix + child), rtol=0, atol=1e-9)
        for link in DRAWN_LINKS[1:-1]:
            # each housing lies on its joint's axis (the link's z through its origin)
            frame = urdf.get_transform(prefix + link, urdf.base_link)
            for end in _cylinder_ends(urdf, f"{prefix}{link}_housing"):
                np.testing.assert_allclose(np.cross(end - frame[:3, 3], frame[:3, 2]), 0.0, atol=1e-9)
        _, base_top = _cylinder_ends(urdf, f"{prefix}base_link_inertia_base")
        shoulder_bottom, _ = _cylinder_ends(urdf, f"{prefix}shoulder_link_housing")
        np.testing.assert_allclose(base_top, shoulder_bottom, rtol=0, atol=1e-9)
        _, plate = _cylinder_ends(urdf, f"{prefix}wrist_3_link_flange")
        np.testing.assert_allclose(plate, _origin_of(urdf, prefix + "flange"), rtol=0, atol=1e-9)


def _all_models_cell(tmp_path: Path) -> Any:
    robots = [
        {"name": name, "model": name, "pose": {"xyz": [2.0 * i, 0.0, 0.0]}} for i, name in enumerate(MODELS)
    ]
    return make_cell(tmp_path, *robots)


def test_every_ur_link_of_every_model_has_visual_and_collision_geometry(tmp_path: Path) -> None:
    root = ET.fromstring(build_cell_urdf(_all_models_cell(tmp_path)))
    links = {link.get("name"): link for link in root.iter("link")}
    for name in MODELS:
        for link in DRAWN_LINKS:
            element = links[f"{name}_{link}"]
            for tag in ("visual", "collision"):
                shapes = [e.find("geometry/cylinder") for e in element.findall(tag)]
                assert shapes, f"{name}_{link} has no <{tag}>"
                for shape in shapes:
                    assert shape is not None, f"{name}_{link}: a <{tag}> without a cylinder"
                    assert float(shape.get("radius", "0")) > 0
                    assert float(shape.get("length", "0")) > 0
    # the two materials the visuals name are defined once, with a colour
    materials = {m.get("name"): m for m in root.findall("material")}
    assert set(materials) == {"urdaemon_ur_housing", "urdaemon_ur_tube"}
    assert all(m.find("color") is not None for m in materials.values())
    named = {m.get("name") for m in root.iter("material") if m.find("color") is None}
    assert named == set(materials)


@pytest.mark.parametrize("name", MODELS)
@pytest.mark.parametrize("variant", ["nominal", "calibrated"])
def test_each_tube_ends_on_its_child_joint_in_a_viewer(tmp_path: Path, name: str, variant: str) -> None:
    rng = np.random.default_rng(300 + 2 * MODELS.index(name) + (variant == "calibrated"))
    robot: dict[str, Any] = {
        "name": "alice",
        "model": name,
        "pose": {"xyz": [0.3, -0.2, 0.1], "rpy": [0.1, 0.2, 0.3]},
    }
    if variant == "calibrated":
        nominal = load_ur_model(name).dh
        robot["calibration"] = str(write_calibration(tmp_path / "cal.yaml", random_calibration(nominal, rng)))
    urdf = _viewer_load(build_cell_urdf(make_cell(tmp_path, robot)))
    _assert_joined_up(urdf, "alice_", rng)


def test_a_calibrated_arms_shapes_follow_its_calibrated_joints(tmp_path: Path) -> None:
    calibration = write_calibration(tmp_path / "cal.yaml", REAL_UR10E)
    cell = make_cell(
        tmp_path,
        {"name": "cal", "model": "ur10e", "calibration": str(calibration)},
        {"name": "nom", "model": "ur10e", "pose": {"xyz": [2.0, 0.0, 0.0]}},
    )
    urdf = _viewer_load(build_cell_urdf(cell))
    rng = np.random.default_rng(31)
    _assert_joined_up(urdf, "cal_", rng)
    urdf.update_cfg(dict.fromkeys(urdf.actuated_joint_names, 0.0))
    offset = np.array([2.0, 0.0, 0.0])
    for link in TUBES:
        _, calibrated = _cylinder_ends(urdf, f"cal_{link}_tube")
        _, nominal = _cylinder_ends(urdf, f"nom_{link}_tube")
        # the calibration moves the joints by millimetres; the tubes move with them
        assert 1e-5 < np.linalg.norm(calibrated + offset - nominal) < 0.02, link


def _radii(root: ET.Element, name: str) -> tuple[float, float]:
    """(elbow housing radius, upper arm tube radius) of robot ``name``."""
    found: dict[str, float] = {}
    for visual in root.iter("visual"):
        cylinder = visual.find("geometry/cylinder")
        assert cylinder is not None
        found[visual.get("name", "")] = float(cylinder.get("radius", "nan"))
    return found[f"{name}_forearm_link_housing"], found[f"{name}_upper_arm_link_tube"]


def test_radii_grow_with_the_model(tmp_path: Path) -> None:
    root = ET.fromstring(build_cell_urdf(_all_models_cell(tmp_path)))
    for series in (("ur3e", "ur5e", "ur10e", "ur20"), ("ur3", "ur5", "ur10")):
        radii = [_radii(root, name) for name in series]
        for (smaller, larger), names in zip(pairwise(radii), pairwise(series), strict=True):
            assert smaller[0] < larger[0], names
            assert smaller[1] < larger[1], names
    # same joint sizes, same radii; and a sane size: a UR5e's upper-arm tube is a few centimetres thick
    assert _radii(root, "ur16e") == _radii(root, "ur10e")
    assert _radii(root, "ur30") == _radii(root, "ur20")
    assert 0.02 < _radii(root, "ur5e")[1] < 0.06


CUSTOM_XACRO = """<?xml version="1.0"?>
<robot xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:macro name="gripper" params="prefix parent *origin">
    <link name="${prefix}base_link">
      <visual name="body">
        <origin xyz="0 0 0.02" rpy="0 0 0"/>
        <geometry><mesh filename="package://gripper/body.stl" scale="0.001 0.001 0.001"/></geometry>
        <material name="gripper_black"><color rgba="0.1 0.1 0.1 1"/></material>
      </visual>
      <collision><geometry><box size="0.05 0.05 0.04"/></geometry></collision>
    </link>
    <joint name="${prefix}mount" type="fixed">
      <parent link="${parent}"/>
      <child link="${prefix}base_link"/>
      <xacro:insert_block name="origin"/>
    </joint>
    <link name="${prefix}finger"/>
    <joint name="${prefix}slide" type="prismatic">
      <parent link="${prefix}base_link"/>
      <child link="${prefix}finger"/>
      <origin xyz="0 0 0.04" rpy="0 0 0"/>
      <axis xyz="1 0 0"/>
      <limit lower="0" upper="0.04" velocity="0.1" effort="20"/>
    </joint>
    <link name="${prefix}tool0"/>
    <joint name="${prefix}tool0_joint" type="fixed">
      <parent link="${prefix}finger"/>
      <child link="${prefix}tool0"/>
    </joint>
  </xacro:macro>
</robot>
"""


def _links(text: str, prefix: str) -> dict[str, bytes]:
    found: dict[str, bytes] = {}
    for link in ET.fromstring(text).iter("link"):
        name = str(link.get("name"))
        if name.startswith(prefix):
            link.tail = None  # the whitespace after it is not the link's
            found[name] = ET.tostring(link)
    return found


def test_a_custom_robot_keeps_its_own_links_byte_for_byte(tmp_path: Path) -> None:
    """A custom robot's links next to UR arms are exactly its xacro's: nothing drawn added or dropped."""
    (tmp_path / "gripper.xacro").write_text(CUSTOM_XACRO, encoding="utf-8")
    custom = {
        "name": "grip",
        "model": "custom",
        "description": {"xacro": "gripper.xacro", "macro": "gripper"},
        "pose": {"parent": "alice_tool0"},
    }
    alone = make_cell(tmp_path, {**custom, "pose": {"parent": "world"}})
    beside = make_cell(tmp_path, {"name": "alice", "model": "ur5e"}, custom)
    expected = _links(build_cell_urdf(alone), "grip_")
    assert _links(build_cell_urdf(beside), "grip_") == expected
    assert expected["grip_finger"] == b'<link name="grip_finger" />'
    assert b"package://gripper/body.stl" in expected["grip_base_link"]
    # and a cell with custom robots only defines no UR materials
    assert ET.fromstring(build_cell_urdf(alone)).findall("material") == []


def test_the_shapes_add_nothing_the_daemon_reads(tmp_path: Path) -> None:
    """The daemon's reader sees the same joints and links with or without the shapes."""
    text = build_cell_urdf(make_cell(tmp_path, {"name": "alice", "model": "ur10e"}))
    root = ET.fromstring(text)
    assert len(list(root.iter("visual"))) == len(list(root.iter("collision"))) == 12
    for link in root.iter("link"):
        for tag in ("visual", "collision"):
            for element in link.findall(tag):
                link.remove(element)
    for material in root.findall("material"):
        root.remove(material)
    bare = ET.tostring(root, encoding="unicode")
    ours, theirs = read_urdf_facts(text), read_urdf_facts(bare)
    assert ours.robot.links == theirs.robot.links
    assert ours.base_link == theirs.base_link
    assert [(j.name, j.parent, j.child, j.origin, j.limit) for j in ours.robot.joints] == [
        (j.name, j.parent, j.child, j.origin, j.limit) for j in theirs.robot.joints
    ]
