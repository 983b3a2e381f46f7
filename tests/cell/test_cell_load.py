"""Good cell files: shipped configs, defaults, default ports, path resolution, frozen models, summary."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from urdaemon.cell import Cell, load_cell, parse_cell, summarize, ur_models
from urdaemon.cell.config import DEFAULT_PORT_BASE, DEFAULT_PORT_STRIDE
from urdaemon.cell.robot_options import Ports
from urdaemon.cell.servo import ServoJoint
from urdaemon.errors import ConfigError
from urdaemon.model import UR_JOINTS

REPO = Path(__file__).resolve().parents[2]
CONFIGS = REPO / "configs"
DUAL = CONFIGS / "dual_robot_mock.yaml"
SERVO = CONFIGS / "servo_arm.yaml"

ROLES = ("reverse", "script_sender", "trajectory", "script_command")


def cell_text(robots: list[dict[str, Any]], **top: Any) -> str:
    """A cell file with the given robot mappings."""
    return yaml.safe_dump({"cell": "c", **top, "robots": robots}, sort_keys=False)


def mock_robot(name: str, ports: dict[str, int] | None = None, **extra: Any) -> dict[str, Any]:
    robot: dict[str, Any] = {"name": name, "model": "ur5e", "backend": "mock", **extra}
    if ports is not None:
        robot["ports"] = ports
    return robot


def block(base: int) -> dict[str, int]:
    return dict(zip(ROLES, range(base, base + 4), strict=True))


# --- the shipped configs ---


def test_dual_robot_mock_loads() -> None:
    cell = load_cell(DUAL)
    assert cell.cell == "demo_cell"
    assert [r.name for r in cell.robots] == ["alice", "bob"]
    assert [r.model for r in cell.robots] == ["ur10e", "ur3e"]
    assert all(r.backend == "mock" for r in cell.robots)
    assert cell.zenoh.mode == "peer"
    assert cell.zenoh.listen == ("tcp/127.0.0.1:7447",)
    assert cell.zenoh.connect == ()
    assert cell.zenoh.multicast_scouting is False
    assert cell.publish.tf_rate_hz == 50.0
    alice, bob = cell.robots
    assert alice.ports.as_dict() == block(50001)
    assert bob.ports.as_dict() == block(50011)
    assert alice.pose.xyz == (0.5, 0.0, 0.0)
    assert bob.pose.rpy == (0.0, 0.0, math.pi)
    assert alice.pose.parent == "world"
    assert alice.mock is not None
    assert alice.mock.initial_positions == (0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0)
    assert alice.prefix == "alice_"
    assert alice.is_ur
    assert cell.robot("bob") is bob
    with pytest.raises(KeyError):
        cell.robot("carol")


def test_servo_arm_loads() -> None:
    cell = load_cell(SERVO)
    assert cell.cell == "demo_servo"
    (arm,) = cell.robots
    assert arm.model == "custom"
    assert not arm.is_ur
    assert arm.backend == "servo"
    assert arm.description is not None
    # the xacro path is resolved against the cell file's folder and made absolute
    assert arm.description.xacro == str((CONFIGS / "servo_arm" / "servo_arm.urdf.xacro").resolve())
    assert arm.description.macro == "servo_arm"
    assert arm.description.default_max_acceleration == 6.0
    assert arm.servo is not None
    assert [j.name for j in arm.servo.joints] == ["base_yaw", "shoulder", "elbow", "wrist"]
    assert [j.channel for j in arm.servo.joints] == [0, 1, 2, 3]
    assert [j.direction for j in arm.servo.joints] == [1, -1, 1, 1]
    assert arm.servo.joints[3].offset == 0.1
    assert arm.servo.joints[2].pulse_min_us == 600.0
    assert arm.servo.pwm_frequency_hz == 50.0
    assert arm.ports.as_dict() == block(50001)


def test_shipped_configs_load_from_another_working_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    cell = load_cell(SERVO)
    assert cell.robots[0].description is not None
    assert Path(cell.robots[0].description.xacro).is_file()


def test_load_cell_accepts_a_string_path() -> None:
    assert load_cell(str(DUAL)) == load_cell(DUAL)


def test_defaults_of_a_minimal_cell() -> None:
    cell = parse_cell("cell: c\nrobots: [{name: alice, model: ur5e, backend: mock}]\n")
    assert cell.zenoh.mode == "peer"
    assert cell.zenoh.listen == ("tcp/127.0.0.1:7447",)
    assert cell.publish.joint_states_decimation == 1
    assert cell.publish.status_rate_hz == 2.0
    (alice,) = cell.robots
    assert alice.headless is True
    assert alice.address is None
    assert alice.calibration is None
    assert alice.pose.xyz == (0.0, 0.0, 0.0)
    assert alice.tcp == (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert alice.motion.stream_timeout == 0.2
    assert alice.motion.goal_tolerance == 0.01
    assert alice.mock is None
    assert alice.joint_limits == {}
    assert alice.ports.as_dict() == block(DEFAULT_PORT_BASE)


def test_tcp_offset_loads_up_to_its_limits() -> None:
    """A TCP at the edge of its range (1 m along an axis, a rotation of exactly pi) is accepted."""
    text = "cell: c\nrobots: [{name: alice, model: ur5e, backend: mock, tcp: [0.1, -1, 1, 0, 0, %r]}]\n"
    (alice,) = parse_cell(text % math.pi).robots
    assert alice.tcp == (0.1, -1.0, 1.0, 0.0, 0.0, math.pi)


def test_ur_models_lists_the_shipped_models() -> None:
    models = ur_models()
    assert models == tuple(sorted(models))
    assert {"ur3", "ur5", "ur10", "ur3e", "ur5e", "ur10e", "ur16e", "ur20", "ur30"} <= set(models)


@pytest.mark.parametrize("model", ur_models())
def test_every_ur_model_is_accepted(model: str) -> None:
    cell = parse_cell(f"cell: c\nrobots: [{{name: alice, model: {model}, backend: mock}}]\n")
    assert cell.robots[0].model == model


def test_valid_variants_load() -> None:
    text = """
cell: Lab-1
zenoh: {mode: client, connect: ["tcp/10.0.0.1:7447", "udp/[::1]:7447"], listen: []}
robots:
  - name: alice
    model: ur10e
    backend: ur
    address: 10.0.0.2
    headless: false
    joint_limits:
      elbow_joint: {min_position: -1.0, max_position: 1.0, max_velocity: 0.5}
  - name: bob
    model: ur3e
    backend: mock
    pose: {parent: alice_tool0, xyz: [0, 0, 0.1]}
    mock: {initial_positions: {elbow_joint: 1.0}, speed_scaling: 0.5, rate_hz: 125}
"""
    cell = parse_cell(text)
    alice, bob = cell.robots
    assert cell.zenoh.connect == ("tcp/10.0.0.1:7447", "udp/[::1]:7447")
    assert cell.zenoh.listen == ()
    assert alice.address == "10.0.0.2"
    assert alice.headless is False
    assert alice.joint_limits["elbow_joint"].max_velocity == 0.5
    assert alice.joint_limits["elbow_joint"].max_acceleration is None
    assert bob.pose.parent == "alice_tool0"
    assert bob.mock is not None
    assert bob.mock.initial_positions == {"elbow_joint": 1.0}
    assert bob.mock.rate_hz == 125.0


def test_custom_model_joint_limits_are_not_checked_against_ur_joints(tmp_path: Path) -> None:
    (tmp_path / "arm.xacro").write_text("<robot/>")
    cell_file = tmp_path / "cell.yaml"
    cell_file.write_text(
        "cell: c\nrobots: [{name: arm, model: custom, backend: mock, "
        "description: {xacro: arm.xacro, macro: arm}, joint_limits: {gripper: {max_velocity: 1.0}}, "
        "mock: {initial_positions: [1, 2]}}]\n"
    )
    cell = load_cell(cell_file)
    assert set(cell.robots[0].joint_limits) == {"gripper"}


# --- relative paths resolve against the cell file's folder ---


def test_calibration_resolves_against_the_cell_file_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = tmp_path / "cells"
    (folder / "cal").mkdir(parents=True)
    (folder / "cal" / "alice.yaml").write_text("x: 1\n")
    cell_file = folder / "cell.yaml"
    cell_file.write_text(cell_text([mock_robot("alice", calibration="cal/alice.yaml")]))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    cell = load_cell(cell_file)
    assert cell.robots[0].calibration == str((folder / "cal" / "alice.yaml").resolve())


def test_calibration_relative_to_cwd_is_not_found_when_cell_file_is_elsewhere(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "calib.yaml").write_text("x: 1\n")
    folder = tmp_path / "cells"
    folder.mkdir()
    cell_file = folder / "cell.yaml"
    cell_file.write_text(cell_text([mock_robot("alice", calibration="calib.yaml")]))
    monkeypatch.chdir(tmp_path)  # calib.yaml exists in the cwd, but not beside the cell file
    with pytest.raises(ConfigError) as info:
        load_cell(cell_file)
    assert info.value.errors == [
        f"{cell_file}: robots[0] (alice).calibration: file not found: {folder / 'calib.yaml'}"
    ]


def test_absolute_calibration_path_is_kept(tmp_path: Path) -> None:
    calib = tmp_path / "abs.yaml"
    calib.write_text("x: 1\n")
    cell = parse_cell(cell_text([mock_robot("alice", calibration=str(calib))]), base_dir=Path("/nonexistent"))
    assert cell.robots[0].calibration == str(calib.resolve())


def test_parse_cell_without_base_dir_resolves_against_cwd(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "calib.yaml").write_text("x: 1\n")
    monkeypatch.chdir(tmp_path)
    cell = parse_cell(cell_text([mock_robot("alice", calibration="calib.yaml")]))
    assert cell.robots[0].calibration == str((tmp_path / "calib.yaml").resolve())


def test_calibration_that_is_a_directory_is_not_found(tmp_path: Path) -> None:
    (tmp_path / "cal").mkdir()
    with pytest.raises(ConfigError, match=r"robots\[0\] \(alice\)\.calibration: file not found"):
        parse_cell(cell_text([mock_robot("alice", calibration="cal")]), base_dir=tmp_path)


# --- frozen models ---


def test_models_are_frozen() -> None:
    cell = load_cell(DUAL)
    robot = cell.robots[0]
    with pytest.raises(ValidationError, match="frozen"):
        cell.cell = "other"
    with pytest.raises(ValidationError, match="frozen"):
        robot.name = "eve"
    with pytest.raises(ValidationError, match="frozen"):
        robot.ports.reverse = 1
    with pytest.raises(ValidationError, match="frozen"):
        robot.pose.parent = "x"
    with pytest.raises(ValidationError, match="frozen"):
        cell.zenoh.mode = "client"
    with pytest.raises(ValidationError, match="frozen"):
        cell.publish.tf_rate_hz = 1.0
    assert isinstance(cell.robots, tuple)
    assert isinstance(robot.pose.xyz, tuple)
    assert robot.mock is not None
    assert isinstance(robot.mock.initial_positions, tuple)
    with pytest.raises(ValidationError, match="frozen"):
        robot.mock.speed_scaling = 0.1
    assert cell.robots[0].name == "alice"


def test_servo_models_are_frozen() -> None:
    cell = load_cell(SERVO)
    servo = cell.robots[0].servo
    assert servo is not None
    joint: ServoJoint = servo.joints[0]
    with pytest.raises(ValidationError, match="frozen"):
        joint.channel = 5
    with pytest.raises(ValidationError, match="frozen"):
        servo.rate_hz = 10.0
    assert isinstance(servo.joints, tuple)


def test_cells_are_hashable_values() -> None:
    assert load_cell(DUAL) == load_cell(DUAL)
    assert hash(load_cell(DUAL).robots[0].ports) == hash(load_cell(DUAL).robots[0].ports)


# --- summary ---


def test_summarize_dual_robot_mock() -> None:
    assert summarize(load_cell(DUAL)).splitlines() == [
        "cell 'demo_cell': 2 robot(s); zenoh peer listen=['tcp/127.0.0.1:7447'] connect=[]",
        "  alice: ur10e backend=mock ports=50001/50002/50003/50004 xyz=[0.5, 0.0, 0.0] "
        "rpy=[0.0, 0.0, 0.0] parent=world",
        "  bob: ur3e backend=mock ports=50011/50012/50013/50014 xyz=[-0.5, 0.0, 0.0] "
        "rpy=[0.0, 0.0, 3.141592653589793] parent=world",
    ]


def test_summarize_shows_address_calibration_and_connect(tmp_path: Path) -> None:
    (tmp_path / "cal.yaml").write_text("x: 1\n")
    text = cell_text(
        [
            {
                "name": "alice",
                "model": "ur5e",
                "backend": "ur",
                "address": "10.0.0.2",
                "calibration": "cal.yaml",
            }
        ],
        zenoh={"mode": "client", "connect": ["tcp/10.0.0.1:7447"]},
    )
    summary = summarize(parse_cell(text, base_dir=tmp_path))
    first, second = summary.splitlines()
    assert first == "cell 'c': 1 robot(s); zenoh client listen=[] connect=['tcp/10.0.0.1:7447']"
    assert second.startswith("  alice: ur5e backend=ur at 10.0.0.2 ports=50001/50002/50003/50004 ")
    assert second.endswith(f" calibration={(tmp_path / 'cal.yaml').resolve()}")


def test_summarize_servo_arm() -> None:
    summary = summarize(load_cell(SERVO))
    assert summary.splitlines()[0].startswith("cell 'demo_servo': 1 robot(s); zenoh peer")
    assert "  arm: custom backend=servo outputs=zenoh servo_command xyz=" in summary
    assert "ports=" not in summary  # a servo arm listens on none
    assert "calibration=" not in summary
    assert " at " not in summary


# --- default port assignment ---


def test_summarize_names_each_servo_output() -> None:
    text = SERVO.read_text().replace(
        "      rate_hz: 50\n",
        "      rate_hz: 50\n"
        "      outputs: [{kind: i2c, address: [0x40, 0x41]}, {kind: serial, port: /dev/ttyACM0}]\n",
    )
    path = SERVO.parent / "servo_arm.yaml"
    summary = summarize(parse_cell(text, source=str(path), base_dir=SERVO.parent))
    assert "outputs=i2c bus 1 (0x40, 0x41), serial /dev/ttyACM0 " in summary


def test_ports_block_and_as_dict() -> None:
    ports = Ports.block(40000)
    assert ports.as_dict() == {
        "reverse": 40000,
        "script_sender": 40001,
        "trajectory": 40002,
        "script_command": 40003,
    }
    assert list(ports.as_dict()) == list(ROLES)


def test_ports_block_refuses_overflow() -> None:
    with pytest.raises(ValidationError):
        Ports.block(65533)


def test_default_ports_are_blocks_ten_apart() -> None:
    cell = parse_cell(cell_text([mock_robot(n) for n in ("a", "b", "c")]))
    assert [r.ports.as_dict() for r in cell.robots] == [block(50001), block(50011), block(50021)]
    assert DEFAULT_PORT_BASE == 50001
    assert DEFAULT_PORT_STRIDE == 10


def test_default_ports_skip_explicit_ones() -> None:
    robots = [mock_robot("a"), mock_robot("b", block(50001)), mock_robot("c"), mock_robot("d", block(50022))]
    cell = parse_cell(cell_text(robots))
    assert [r.ports.as_dict() for r in cell.robots] == [
        block(50011),
        block(50001),
        block(50031),
        block(50022),
    ]


def test_default_ports_skip_a_single_explicit_port_anywhere_in_the_block() -> None:
    explicit = {"reverse": 1000, "script_sender": 1001, "trajectory": 1002, "script_command": 50004}
    cell = parse_cell(cell_text([mock_robot("a"), mock_robot("b", explicit)]))
    assert cell.robots[0].ports.as_dict() == block(50011)
    assert cell.robots[1].ports.as_dict() == explicit


def test_default_ports_use_the_lowest_free_block() -> None:
    # 50001.. is taken, 50011.. is free: the first default robot gets 50011, the second 50021
    cell = parse_cell(cell_text([mock_robot("a", block(50001)), mock_robot("b"), mock_robot("c")]))
    assert [r.ports.as_dict() for r in cell.robots] == [block(50001), block(50011), block(50021)]


def test_explicit_null_ports_get_defaults() -> None:
    cell = parse_cell("cell: c\nrobots: [{name: a, model: ur5e, backend: mock, ports: null}]\n")
    assert cell.robots[0].ports.as_dict() == block(50001)


def test_empty_ports_mapping_is_not_defaulted() -> None:
    with pytest.raises(ConfigError) as info:
        parse_cell("cell: c\nrobots: [{name: a, model: ur5e, backend: mock, ports: {}}]\n")
    assert [line.split(": ")[1] for line in info.value.errors] == [
        f"robots[0] (a).ports.{role}" for role in ROLES
    ]


def test_default_ports_never_clash_with_quoted_or_float_explicit_ports() -> None:
    text = (
        "cell: c\nrobots:\n  - {name: a, model: ur5e, backend: mock}\n"
        "  - {name: b, model: ur5e, backend: mock, ports: "
        "{reverse: '50001', script_sender: '50002', trajectory: 50003.0, script_command: '50004'}}\n"
    )
    outcome = try_parse(text)
    if isinstance(outcome, ConfigError):
        # refusing the non-integer ports is fine too; blaming robot 'a' for a clash is not
        assert not any("clashes" in line for line in outcome.errors), outcome.errors
    else:
        ports = [p for r in outcome.robots for p in r.ports.as_dict().values()]
        assert len(set(ports)) == len(ports)


def try_parse(text: str) -> Cell | ConfigError:
    """The cell, or the error parsing it raised."""
    try:
        return parse_cell(text)
    except ConfigError as err:
        return err


PORT_CHOICES = st.one_of(
    st.sampled_from([50001, 50002, 50004, 50005, 50011, 50013, 50021, 50024, 50031, 50041]),
    st.integers(min_value=50000, max_value=50060),
)


@st.composite
def robot_lists(draw: st.DrawFn) -> list[dict[str, Any]]:
    n = draw(st.integers(min_value=1, max_value=6))
    robots = []
    for i in range(n):
        explicit = draw(st.booleans())
        if explicit:
            if draw(st.booleans()):
                ports = block(draw(PORT_CHOICES))
            else:
                ports = {role: draw(PORT_CHOICES) for role in ROLES}
            robots.append(mock_robot(f"r{i}", ports))
        else:
            robots.append(mock_robot(f"r{i}"))
    return robots


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(robot_lists())
def test_ports_are_distinct_or_the_clash_is_reported(robots: list[dict[str, Any]]) -> None:
    explicit = [r["ports"] for r in robots if "ports" in r]
    explicit_ports = [p for ports in explicit for p in ports.values()]
    explicit_clash = len(set(explicit_ports)) != len(explicit_ports)
    cell = try_parse(cell_text(robots))
    if isinstance(cell, ConfigError):
        assert explicit_clash, f"refused although explicit ports do not clash: {cell.errors}"
        assert cell.errors
        for line in cell.errors:
            assert "clashes" in line or "port" in line, line
        return
    assert not explicit_clash, "explicit ports clash but the cell was accepted"
    ports = [p for r in cell.robots for p in r.ports.as_dict().values()]
    assert len(set(ports)) == len(ports)
    defaults: list[int] = []
    for given_robot, robot in zip(robots, cell.robots, strict=True):
        got = robot.ports.as_dict()
        if "ports" in given_robot:
            assert got == given_robot["ports"]
        else:
            base = got["reverse"]
            assert (base - DEFAULT_PORT_BASE) % DEFAULT_PORT_STRIDE == 0
            assert got == block(base)
            assert not set(got.values()) & set(explicit_ports)
            defaults.append(base)
    assert defaults == sorted(defaults)
    if defaults:
        # the first default robot gets the lowest block that no explicit port touches
        lowest = DEFAULT_PORT_BASE
        while set(range(lowest, lowest + 4)) & set(explicit_ports):
            lowest += DEFAULT_PORT_STRIDE
        assert defaults[0] == lowest


@settings(max_examples=100, deadline=None)
@given(st.lists(st.sampled_from(["cell", "robots", "zenoh", "publish", "color", "robot"]), unique=True))
def test_top_level_keys_are_checked(keys: list[str]) -> None:
    values: dict[str, Any] = {
        "cell": "c",
        "robots": [mock_robot("a")],
        "zenoh": {"mode": "peer"},
        "publish": {"tf_rate_hz": 10},
        "color": "red",
        "robot": {},
    }
    text = yaml.safe_dump({k: values[k] for k in keys})
    valid = {"cell", "robots"} <= set(keys) and not {"color", "robot"} & set(keys)
    if valid:
        assert isinstance(parse_cell(text), Cell)
        return
    with pytest.raises(ConfigError) as info:
        parse_cell(text)
    for key in {"color", "robot"} & set(keys):
        assert f"<string>: {key}: unknown key (not part of the cell file format)" in info.value.errors
    for key in {"cell", "robots"} - set(keys):
        assert f"<string>: {key}: required key is missing" in info.value.errors


def test_joint_limit_override_for_every_ur_joint_is_accepted() -> None:
    limits = {j: {"max_velocity": 1.0} for j in UR_JOINTS}
    cell = parse_cell(cell_text([mock_robot("a", joint_limits=limits)]))
    assert set(cell.robots[0].joint_limits) == set(UR_JOINTS)
