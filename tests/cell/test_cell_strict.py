"""The cell file is strict where the user writes numbers and flags: text is no number, a flag is no
integer, a float is no whole number, and rates stay within what a control loop can mean. Every refusal
names the key path."""

from __future__ import annotations

import pytest

from urdaemon.cell import parse_cell
from urdaemon.cell.load import load_yaml
from urdaemon.errors import ConfigError

ALICE = "{name: alice, model: ur5e, backend: mock"
SERVO = (
    "{name: arm, model: custom, backend: servo, "
    "description: {xacro: servo_arm/servo_arm.urdf.xacro, macro: servo_arm}, "
    "servo: {joints: [{name: j1, channel: 0}]"
)


def errors_of(text: str) -> list[str]:
    """The error lines loading ``text`` gives (resolving files against configs/)."""
    from tests.test_configs import CONFIGS

    with pytest.raises(ConfigError) as info:
        parse_cell(text, source="c.yaml", base_dir=CONFIGS)
    return info.value.errors


def robot(extra: str) -> str:
    return f"cell: c\nrobots: [{ALICE}{extra}}}]\n"


LOOSE = [
    # (cell text, the key path named, a word of the reason)
    (robot(', mock: {rate_hz: "50"}'), "robots[0] (alice).mock.rate_hz", "the text '50'"),
    (robot(", mock: {rate_hz: true}"), "robots[0] (alice).mock.rate_hz", "not true"),
    (robot(", mock: {speed_scaling: '0.5'}"), "robots[0] (alice).mock.speed_scaling", "a number"),
    (
        robot(", mock: {initial_positions: [0, 0, 0, 0, 0, true]}"),
        "robots[0] (alice).mock.initial_positions[5]",
        "not true",
    ),
    (
        robot(", mock: {initial_positions: {elbow_joint: '1'}}"),
        "robots[0] (alice).mock.initial_positions.elbow_joint",
        "a number",
    ),
    (robot(", tcp: [0, 0, '0.1', 0, 0, 0]"), "robots[0] (alice).tcp[2]", "the text '0.1'"),
    (robot(", headless: 1"), "robots[0] (alice).headless", "true or false"),
    (robot(", headless: 'yes'"), "robots[0] (alice).headless", "true or false"),
    (robot(", motion: {goal_tolerance: '0.01'}"), "robots[0] (alice).motion.goal_tolerance", "a number"),
    (
        robot(", joint_limits: {elbow_joint: {max_velocity: false}}"),
        "robots[0] (alice).joint_limits.elbow_joint.max_velocity",
        "not false",
    ),
    (
        robot(", ports: {reverse: 50001.0, script_sender: 50002, trajectory: 50003, script_command: 50004}"),
        "robots[0] (alice).ports.reverse",
        "an integer",
    ),
    (
        "cell: c\npublish: {joint_states_decimation: true}\nrobots: [" + ALICE + "}]\n",
        "publish.joint_states_decimation",
        "an integer, not true",
    ),
    (
        "cell: c\npublish: {joint_states_decimation: 2.0}\nrobots: [" + ALICE + "}]\n",
        "publish.joint_states_decimation",
        "an integer, not 2.0",
    ),
    (
        "cell: c\npublish: {tf_rate_hz: '50'}\nrobots: [" + ALICE + "}]\n",
        "publish.tf_rate_hz",
        "without quotes",
    ),
    ("cell: c\ncommand_lease: 0\nrobots: [" + ALICE + "}]\n", "command_lease", "true or false"),
    ("cell: c\nrecord: {dir: /tmp, ring_s: '60'}\nrobots: [" + ALICE + "}]\n", "record.ring_s", "a number"),
    (
        "cell: c\nrecord: {dir: /tmp, max_mb: true}\nrobots: [" + ALICE + "}]\n",
        "record.max_mb",
        "an integer",
    ),
    ("cell: c\nrobots: [" + SERVO + ", rate_hz: '50'}}]\n", "robots[0] (arm).servo.rate_hz", "a number"),
    (
        "cell: c\nrobots: [" + SERVO.replace("channel: 0", "channel: true") + "}}]\n",
        "robots[0] (arm).servo.joints[0] (j1).channel",
        "an integer",
    ),
    (
        "cell: c\nrobots: [{name: alice, model: ur5e, backend: ur, address: 127.0.0.5, "
        "ur: {read_only: 1}}]\n",
        "robots[0] (alice).ur.read_only",
        "true or false",
    ),
]


@pytest.mark.parametrize(("text", "path", "reason"), LOOSE, ids=[case[1] + ":" + case[2] for case in LOOSE])
def test_loose_types_are_refused_naming_the_key_path(text: str, path: str, reason: str) -> None:
    errors = errors_of(text)
    matching = [line for line in errors if line.startswith(f"c.yaml: {path}: ")]
    assert matching, errors
    assert any(reason in line for line in matching), errors


ABSURD_RATES = [
    (robot(", mock: {rate_hz: 0.001}"), "robots[0] (alice).mock.rate_hz"),
    (robot(", mock: {rate_hz: 5}"), "robots[0] (alice).mock.rate_hz"),
    (robot(", mock: {rate_hz: 2000}"), "robots[0] (alice).mock.rate_hz"),
    (robot(", motion: {feedback_rate_hz: 0.001}"), "robots[0] (alice).motion.feedback_rate_hz"),
    ("cell: c\npublish: {tf_rate_hz: 0.001}\nrobots: [" + ALICE + "}]\n", "publish.tf_rate_hz"),
    ("cell: c\npublish: {io_rate_hz: 0.001}\nrobots: [" + ALICE + "}]\n", "publish.io_rate_hz"),
    ("cell: c\npublish: {status_rate_hz: 0.001}\nrobots: [" + ALICE + "}]\n", "publish.status_rate_hz"),
    ("cell: c\nrobots: [" + SERVO + ", rate_hz: 0.001}}]\n", "robots[0] (arm).servo.rate_hz"),
]


@pytest.mark.parametrize(("text", "path"), ABSURD_RATES, ids=[case[1] for case in ABSURD_RATES])
def test_absurd_rates_are_refused_naming_the_key_path(text: str, path: str) -> None:
    errors = errors_of(text)
    assert any(line.startswith(f"c.yaml: {path}: ") for line in errors), errors


def test_numbers_as_yaml_writes_them_are_accepted() -> None:
    """An integer where a float is wanted, a YAML 1.2 exponent, lists where the schema keeps tuples."""
    from tests.test_configs import CONFIGS

    cell = parse_cell(
        robot(
            ", mock: {rate_hz: 125, initial_positions: [0, -1, 1, 0, 1e-3, 0]}, tcp: [0, 0, 1, 0, 0, 0]"
        ).replace("robots:", "publish: {tf_rate_hz: 10, status_rate_hz: 0.01}\nrobots:"),
        base_dir=CONFIGS,
    )
    mock = cell.robots[0].mock
    assert mock is not None
    assert mock.rate_hz == 125.0
    assert isinstance(mock.rate_hz, float)
    assert mock.initial_positions == (0.0, -1.0, 1.0, 0.0, 0.001, 0.0)
    assert cell.robots[0].tcp[2] == 1.0
    assert cell.publish.tf_rate_hz == 10.0


def test_yaml_exponents_without_a_dot_are_numbers() -> None:
    assert load_yaml("a: [1e3, 25e6, -1.5e-3, 1.0e+3, '1e3', 1e, 12]", "x") == {
        "a": [1000.0, 25e6, -1.5e-3, 1000.0, "1e3", "1e", 12]
    }
