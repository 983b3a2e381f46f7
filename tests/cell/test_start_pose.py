"""A start pose (``mock``/``servo.initial_positions``) outside the arm's limits is bad input: ``check``
and ``serve`` both exit 2 with every offending key path, and ``serve`` finds it before it opens Zenoh
or a port, so a busy machine cannot turn it into another failure (issue 32: ``check`` exited 2 but
``serve`` 1, with no key path)."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import run_cli
from urdaemon.cell import parse_cell
from urdaemon.cli.exit_codes import EXIT_BAD_INPUT
from urdaemon.daemon import describe_cell
from urdaemon.errors import ConfigError

REPO = Path(__file__).resolve().parents[2]
SERVO_XACRO = REPO / "configs" / "servo_arm" / "servo_arm.urdf.xacro"


def mock_cell(positions: str) -> str:
    robot = f"{{name: alice, model: ur5e, backend: mock, mock: {{initial_positions: {positions}}}}}"
    return f"cell: c\nrobots:\n  - {robot}\n"


def servo_cell(positions: str) -> str:
    servo = (REPO / "configs" / "servo_arm.yaml").read_text(encoding="utf-8")
    servo = servo.replace("servo_arm/servo_arm.urdf.xacro", str(SERVO_XACRO))
    return servo.replace("      rate_hz: 50\n", f"      rate_hz: 50\n      initial_positions: {positions}\n")


BAD = {
    "mock list": (
        mock_cell("[9, 0, 0, 0, 0, -7]"),
        [
            "robots[0] (alice).mock.initial_positions[0]: 9 is outside the limits of alice_shoulder_pan",
            "robots[0] (alice).mock.initial_positions[5]: -7 is outside the limits of alice_wrist_3_joint",
        ],
    ),
    "mock mapping": (
        mock_cell("{elbow_joint: 4}"),
        ["robots[0] (alice).mock.initial_positions.elbow_joint: 4 is outside the limits of alice_elbow"],
    ),
    "servo mapping": (
        servo_cell("{elbow: 3.0, wrist: -1.5}"),
        [
            "robots[0] (arm).servo.initial_positions.elbow: 3 is outside the limits of arm_elbow [-2, 2]",
            "robots[0] (arm).servo.initial_positions.wrist: -1.5 is outside the limits of arm_wrist",
        ],
    ),
    "servo unknown joint": (
        servo_cell("{elbow: 0.5, knee: 0.1}"),
        ["robots[0] (arm).servo.initial_positions: unknown joint(s) knee"],
    ),
}


@pytest.mark.parametrize("case", list(BAD))
def test_describe_cell_names_every_key_path(case: str) -> None:
    text, expected = BAD[case]
    with pytest.raises(ConfigError) as info:
        describe_cell(parse_cell(text))
    assert len(info.value.errors) == len(expected), info.value.errors
    for line, wanted in zip(info.value.errors, expected, strict=True):
        assert line.startswith(wanted), info.value.errors


@pytest.mark.parametrize("command", ["check", "serve"])
@pytest.mark.parametrize("case", list(BAD))
def test_check_and_serve_exit_2_naming_the_file_and_key_path(command: str, case: str, tmp_path: Path) -> None:
    text, expected = BAD[case]
    path = tmp_path / "cell.yaml"
    path.write_text(text, encoding="utf-8")
    run = run_cli(
        command, "--config", str(path), *(("--listen", "tcp/127.0.0.1:0") if command == "serve" else ())
    )
    assert run.code == EXIT_BAD_INPUT, run
    for wanted in expected:
        assert f"{path}: {wanted}" in run.stderr, run.stderr
    assert "Traceback" not in run.stderr


def test_serve_finds_a_bad_start_pose_before_its_zenoh_port(tmp_path: Path) -> None:
    """The listen endpoint is taken: the start pose is still what ``serve`` reports, with exit 2."""
    path = tmp_path / "cell.yaml"
    path.write_text(BAD["mock list"][0], encoding="utf-8")
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        port = holder.getsockname()[1]
        run = run_cli("serve", "--config", str(path), "--listen", f"tcp/127.0.0.1:{port}")
    assert run.code == EXIT_BAD_INPUT, run
    assert f"{path}: robots[0] (alice).mock.initial_positions[0]" in run.stderr, run.stderr


def test_serve_as_a_process_exits_2_naming_the_key_path(tmp_path: Path) -> None:
    path = tmp_path / "cell.yaml"
    path.write_text(BAD["servo mapping"][0], encoding="utf-8")
    proc = subprocess.run(
        [sys.executable, "-m", "urdaemon", "serve", "--config", str(path), "--listen", "tcp/127.0.0.1:0"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=REPO,
        check=False,
    )
    assert proc.returncode == EXIT_BAD_INPUT, proc.stderr
    assert f"{path}: robots[0] (arm).servo.initial_positions.elbow: 3 is outside" in proc.stderr
    assert "Traceback" not in proc.stderr
