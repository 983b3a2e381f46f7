"""``urdaemon check --config FILE``: exit 0 and a summary for good cells, else exit 2 and errors."""

from __future__ import annotations

import contextlib
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.helpers import run_cli
from urdaemon.cell import load_cell, summarize

from .test_cell_errors import BAD_CELLS

REPO = Path(__file__).resolve().parents[2]
CONFIGS = REPO / "configs"


def run_check(
    config: str | Path, *, cwd: Path = REPO, extra: tuple[str, ...] = ()
) -> subprocess.CompletedProcess[str]:
    """``urdaemon check --config CONFIG`` run in-process from ``cwd`` (a new interpreter per case
    would add ~1.7 s of imports and test nothing more)."""
    with contextlib.chdir(cwd):
        run = run_cli("check", "--config", str(config), *extra)
    return subprocess.CompletedProcess(["urdaemon", "check"], run.code, run.stdout, run.stderr)


def error_lines(stderr: str) -> list[str]:
    """The indented error lines that follow ``N error(s):`` on stderr."""
    lines = stderr.splitlines()
    heads = [i for i, line in enumerate(lines) if line.endswith(" error(s):")]
    assert heads, stderr
    start = heads[-1]
    count = int(lines[start].split()[0])
    body = [line.removeprefix("  ") for line in lines[start + 1 : start + 1 + count]]
    assert len(body) == count
    return body


@pytest.mark.parametrize(
    ("name", "robots"),
    [
        ("dual_robot_mock.yaml", {"alice": 6, "bob": 6}),
        ("servo_arm.yaml", {"arm": 4}),
    ],
)
def test_check_good_shipped_config(name: str, robots: dict[str, int]) -> None:
    path = CONFIGS / name
    proc = run_check(path)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout.splitlines()
    summary = summarize(load_cell(path)).splitlines()
    assert out[: len(summary)] == summary
    assert out[-1] == "ok"
    joint_lines = out[len(summary) : -1]
    assert len(joint_lines) == len(robots)
    for line, (robot, dof) in zip(joint_lines, robots.items(), strict=True):
        assert line.startswith(f"  {robot}: {dof} joints: ")
        names = line.split(" joints: ", 1)[1].split(", ")
        assert len(names) == dof
        assert all(n.startswith(f"{robot}_") for n in names)
    assert "error" not in proc.stderr.lower()


def test_check_with_relative_path_from_the_config_folder() -> None:
    proc = run_check("servo_arm.yaml", cwd=CONFIGS)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines()[-1] == "ok"


CLI_BAD = [
    "unknown-robot-key",
    "port-above-65535",
    "calibration-not-found",
    "servo-duplicate-channels",
    "servo-i2c-address-too-high",
    "servo-pulse-longer-than-the-period",
    "zenoh-client-without-connect",
    "duplicate-robot-names",
]


@pytest.mark.parametrize("case_id", CLI_BAD)
def test_check_bad_config_exits_2_with_file_and_key_path(tmp_path: Path, case_id: str) -> None:
    case = BAD_CELLS[case_id]
    path = tmp_path / "cell.yaml"
    path.write_text(case.text)
    proc = run_check(path)
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    assert proc.stdout == ""
    lines = error_lines(proc.stderr)
    assert all(line.startswith(f"{path}: ") for line in lines), lines
    assert any(
        line.startswith(f"{path}: {case.path}: ") and case.reason.lower() in line.lower() for line in lines
    ), lines


def test_check_reports_every_error(tmp_path: Path) -> None:
    path = tmp_path / "cell.yaml"
    path.write_text(
        "cell: c\nrobots:\n  - {name: alice, model: ur7, backend: mock}\n"
        "  - {name: bob, model: ur5e, backend: mock, ports: {reverse: 70000, script_sender: 2, "
        "trajectory: 3, script_command: 4}}\n"
    )
    proc = run_check(path)
    assert proc.returncode == 2
    assert "2 error(s):" in proc.stderr
    lines = error_lines(proc.stderr)
    assert lines[0].startswith(f"{path}: robots[0] (alice).model: unknown model 'ur7'")
    assert lines[1] == f"{path}: robots[1] (bob).ports.reverse: Input should be less than or equal to 65535"


def test_check_invalid_yaml_names_line_and_column(tmp_path: Path) -> None:
    path = tmp_path / "cell.yaml"
    path.write_text("cell: c\n  robots: x\n")
    proc = run_check(path)
    assert proc.returncode == 2
    assert error_lines(proc.stderr) == [
        f"{path} (line 2, column 9): not valid YAML: mapping values are not allowed here"
    ]


def test_check_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "missing.yaml"
    proc = run_check(path)
    assert proc.returncode == 2
    assert f"{path}: cannot read" in proc.stderr
    assert proc.stdout == ""


def test_check_without_config_argument_is_a_usage_error() -> None:
    run = run_cli("check")
    assert run.code == 2
    assert "--config" in run.stderr


def test_check_broken_calibration_file_exits_2(tmp_path: Path) -> None:
    (tmp_path / "cal.yaml").write_text("foo: 1\n")
    path = tmp_path / "cell.yaml"
    path.write_text("cell: c\nrobots: [{name: alice, model: ur5e, backend: mock, calibration: cal.yaml}]\n")
    proc = run_check(path)
    assert proc.returncode == 2
    assert str(tmp_path / "cal.yaml") in proc.stderr
    assert "alice" in proc.stderr
    assert proc.stdout == ""


@pytest.mark.parametrize(
    ("old", "new", "said"),
    [
        ("name: wrist, channel: 3", "name: wristx, channel: 3", "servo.joints: wristx not in the robot's"),
        ("      rate_hz: 50\n", "      rate_hz: 50\n      initial_positions: {bogus: 1.0}\n", "bogus"),
        (
            "wrist: {min_position: -1.4708, max_position: 1.4708}",
            "wrist: {min_position: -1.6}",
            "robot 'arm': servo.joints (wrist): the joint's limits [-1.6, 1.5708] rad take the servo to",
        ),
    ],
    ids=[
        "servo-joint-not-in-description",
        "servo-initial-position-unknown-joint",
        "servo-joint-limits-past-the-servo",
    ],
)
def test_check_refuses_servo_config_that_serve_would_refuse(
    tmp_path: Path, old: str, new: str, said: str
) -> None:
    shutil.copytree(CONFIGS / "servo_arm", tmp_path / "servo_arm")
    text = (CONFIGS / "servo_arm.yaml").read_text()
    assert old in text
    path = tmp_path / "servo.yaml"
    path.write_text(text.replace(old, new))
    proc = run_check(path)
    assert proc.returncode == 2, proc.stdout
    assert said in proc.stderr
