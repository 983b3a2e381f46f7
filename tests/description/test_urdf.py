"""Reading the cell URDF back, and each robot's joint limits."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from urdaemon.description import build_cell_urdf, joint_limits_for, load_ur_model, load_urdf
from urdaemon.errors import DescriptionError
from urdaemon.model import UR_JOINTS

from .support import DATA, make_cell

TWO_JOINT = {"xacro": str(DATA / "two_joint_arm.xacro"), "macro": "two_joint_arm"}


@pytest.mark.parametrize("model", ["ur10e", "ur3e", "ur30"])
def test_ur_limits_are_the_models(tmp_path: Path, model: str) -> None:
    cell = make_cell(tmp_path, {"name": "alice", "model": model})
    limits = joint_limits_for(cell.robot("alice"), load_urdf(build_cell_urdf(cell)))
    data = load_ur_model(model)
    assert limits.names == tuple(f"alice_{j}" for j in UR_JOINTS)
    for i, joint in enumerate(data.joints):
        if joint.continuous:
            assert (limits.min_position[i], limits.max_position[i]) == (-math.inf, math.inf)
        else:
            assert (limits.min_position[i], limits.max_position[i]) == (
                joint.min_position,
                joint.max_position,
            )
        assert limits.max_velocity[i] == joint.max_velocity
        assert limits.max_effort[i] == joint.max_effort
        assert limits.max_acceleration[i] == joint.max_acceleration
        assert limits.max_jerk[i] == joint.max_jerk


def test_ur_overrides_are_applied(tmp_path: Path) -> None:
    cell = make_cell(
        tmp_path,
        {
            "name": "alice",
            "model": "ur3e",
            "joint_limits": {
                "shoulder_pan_joint": {"min_position": -1.0, "max_position": 2.0},
                "elbow_joint": {"max_velocity": 0.5, "max_acceleration": 1.5, "max_jerk": 9.0},
                "wrist_3_joint": {"min_position": -3.0, "max_position": 3.0},
            },
        },
    )
    limits = joint_limits_for(cell.robot("alice"), load_urdf(build_cell_urdf(cell)))
    assert (limits.min_position[0], limits.max_position[0]) == (-1.0, 2.0)
    assert (limits.max_velocity[2], limits.max_acceleration[2], limits.max_jerk[2]) == (0.5, 1.5, 9.0)
    assert (limits.min_position[5], limits.max_position[5]) == (-3.0, 3.0)
    # untouched joints keep the model's values
    assert limits.max_velocity[0] == load_ur_model("ur3e").joints[0].max_velocity
    assert limits.max_acceleration[1] == 5.0


def test_overrides_apply_even_to_a_urdf_built_without_them(tmp_path: Path) -> None:
    plain = make_cell(tmp_path, {"name": "alice", "model": "ur10e"})
    tight = make_cell(
        tmp_path,
        {
            "name": "alice",
            "model": "ur10e",
            "joint_limits": {"wrist_1_joint": {"max_position": 0.5, "max_velocity": 0.1}},
        },
    )
    limits = joint_limits_for(tight.robot("alice"), load_urdf(build_cell_urdf(plain)))
    assert (limits.max_position[3], limits.max_velocity[3]) == (0.5, 0.1)


def test_custom_robot_limits_come_from_its_xacro(tmp_path: Path) -> None:
    description = {**TWO_JOINT, "default_max_acceleration": 2.5, "default_max_jerk": 25.0}
    cell = make_cell(
        tmp_path,
        {
            "name": "arm",
            "model": "custom",
            "description": description,
            "joint_limits": {"reach": {"max_position": 0.2, "max_jerk": 4.0}},
        },
    )
    text = build_cell_urdf(cell)
    assert 'upper="0.2"' in text  # the position override went into the URDF too
    limits = joint_limits_for(cell.robot("arm"), load_urdf(text))
    assert limits.names == ("arm_yaw", "arm_reach")  # the mimic finger is not commanded
    assert limits.min_position == (-2.0, 0.0)
    assert limits.max_position == (2.0, 0.2)
    assert limits.max_velocity == (1.5, 0.2)
    assert limits.max_effort == (10.0, 50.0)
    assert limits.max_acceleration == (2.5, 2.5)
    assert limits.max_jerk == (25.0, 4.0)


def test_custom_joint_without_velocity_limit(tmp_path: Path) -> None:
    xacro = tmp_path / "slow.xacro"
    xacro.write_text(
        (DATA / "two_joint_arm.xacro").read_text(encoding="utf-8").replace('velocity="1.5" ', ""),
        encoding="utf-8",
    )
    cell = make_cell(
        tmp_path,
        {"name": "arm", "model": "custom", "description": {"xacro": "slow.xacro", "macro": "two_joint_arm"}},
    )
    urdf = load_urdf(build_cell_urdf(cell))
    with pytest.raises(
        DescriptionError, match=r"robot 'arm': joint 'arm_yaw' has no positive <limit velocity>"
    ):
        joint_limits_for(cell.robot("arm"), urdf)
    # ... which the cell file can supply
    fixed = make_cell(
        tmp_path,
        {
            "name": "arm",
            "model": "custom",
            "description": {"xacro": "slow.xacro", "macro": "two_joint_arm"},
            "joint_limits": {"yaw": {"max_velocity": 0.7}},
        },
    )
    assert joint_limits_for(fixed.robot("arm"), load_urdf(build_cell_urdf(fixed))).max_velocity[0] == 0.7


def test_load_urdf_rejects_garbage() -> None:
    with pytest.raises(DescriptionError, match="cannot read the URDF"):
        load_urdf("<robot name='x'><joint name='j' type='revolute'><parent link='nope'/></joint></robot>")
