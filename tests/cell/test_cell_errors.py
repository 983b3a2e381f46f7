"""Bad cell files: every one is refused with a ``ConfigError`` naming the file, the key path and the reason.

Each case is a complete cell file written into ``tmp_path`` and loaded with ``load_cell``; the
assertion is on one error line of the form ``<file>: <key path>: <reason>``.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import pytest

from urdaemon.cell import load_cell, parse_cell
from urdaemon.errors import ConfigError

ALICE = "{name: alice, model: ur5e, backend: mock"
"""The opening of a minimal valid robot in flow style; cases append their own keys and the closing brace."""
BOB = "{name: bob, model: ur3e, backend: mock"
PORTS_A = "{reverse: 50001, script_sender: 50002, trajectory: 50003, script_command: 50004}"
SERVO_ARM = (
    "{name: arm, model: custom, backend: servo, description: {xacro: arm.xacro, macro: arm}, "
    "servo: {joints: [JOINTS]}}"
)


def servo_cell(joints: str, servo_extra: str = "") -> str:
    """A servo-arm cell whose servo section lists ``joints`` (flow style) plus ``servo_extra`` keys."""
    robot = SERVO_ARM.replace("[JOINTS]", f"[{joints}]{servo_extra}")
    return f"cell: c\nrobots: [{robot}]\n"


def one_robot(extra: str) -> str:
    """A cell with alice carrying ``extra`` (``, key: value`` pairs)."""
    return f"cell: c\nrobots: [{ALICE}{extra}}}]\n"


class Bad(NamedTuple):
    """A bad cell file, the key path its error must name and a word of the reason."""

    text: str
    path: str
    reason: str


BAD_CELLS: dict[str, Bad] = {
    # --- unknown keys, at every level ---
    "unknown-top-level-key": Bad("cell: c\ncolour: red\nrobots: [" + ALICE + "}]\n", "colour", "unknown key"),
    "unknown-zenoh-key": Bad(
        "cell: c\nzenoh: {mode: peer, lisen: ['tcp/127.0.0.1:7447']}\nrobots: [" + ALICE + "}]\n",
        "zenoh.lisen",
        "unknown key",
    ),
    "unknown-publish-key": Bad(
        "cell: c\npublish: {tf_rate: 10}\nrobots: [" + ALICE + "}]\n", "publish.tf_rate", "unknown key"
    ),
    "read-only-with-startup": Bad(
        "cell: c\nrobots: [{name: alice, model: ur5e, backend: ur, address: 127.0.0.5, "
        "ur: {read_only: true, startup: true}}]\n",
        "robots[0] (alice).ur",
        "cannot also be started up",
    ),
    "unknown-robot-key": Bad(one_robot(", adress: 10.0.0.2"), "robots[0] (alice).adress", "unknown key"),
    "unknown-ports-key": Bad(
        one_robot(
            ", ports: {reverse: 50001, script_sender: 50002, trajectory: 50003, script_command: 50004, "
            "rtde: 30004}"
        ),
        "robots[0] (alice).ports.rtde",
        "unknown key",
    ),
    "unknown-pose-key": Bad(
        one_robot(", pose: {xyzz: [0, 0, 0]}"), "robots[0] (alice).pose.xyzz", "unknown key"
    ),
    "unknown-joint-limit-key": Bad(
        one_robot(", joint_limits: {elbow_joint: {max_vel: 1.0}}"),
        "robots[0] (alice).joint_limits.elbow_joint.max_vel",
        "unknown key",
    ),
    "unknown-motion-key": Bad(
        one_robot(", motion: {path_tol: 0.1}"), "robots[0] (alice).motion.path_tol", "unknown key"
    ),
    "unknown-mock-key": Bad(one_robot(", mock: {speed: 0.5}"), "robots[0] (alice).mock.speed", "unknown key"),
    "unknown-servo-key": Bad(
        servo_cell("{name: j1, channel: 0}", ", freq: 50"), "robots[0] (arm).servo.freq", "unknown key"
    ),
    "unknown-servo-joint-key": Bad(
        servo_cell("{name: j1, chanel: 0}"), "robots[0] (arm).servo.joints[0] (j1).chanel", "unknown key"
    ),
    "unknown-description-key": Bad(
        "cell: c\nrobots: [{name: arm, model: custom, backend: mock, "
        "description: {xacro: arm.xacro, macro: arm, macros: [x]}}]\n",
        "robots[0] (arm).description.macros",
        "unknown key",
    ),
    # --- missing / empty top-level keys ---
    "missing-cell": Bad("robots: [" + ALICE + "}]\n", "cell", "missing"),
    "missing-robots": Bad("cell: c\n", "robots", "missing"),
    "empty-robots": Bad("cell: c\nrobots: []\n", "robots", "at least one robot"),
    "robots-not-a-list": Bad("cell: c\nrobots: {alice: 1}\n", "robots", "tuple"),
    "robot-not-a-mapping": Bad("cell: c\nrobots: [alice]\n", "robots[0]", "dictionary"),
    "missing-robot-model": Bad(
        "cell: c\nrobots: [{name: alice, backend: mock}]\n", "robots[0] (alice).model", "missing"
    ),
    "missing-robot-backend": Bad(
        "cell: c\nrobots: [{name: alice, model: ur5e}]\n", "robots[0] (alice).backend", "missing"
    ),
    # --- names ---
    "duplicate-robot-names": Bad(
        "cell: c\nrobots: [" + ALICE + "}, " + ALICE + "}]\n", "robots[1] (alice).name", "duplicate"
    ),
    "robot-name-upper-case": Bad(
        "cell: c\nrobots: [{name: Alice, model: ur5e, backend: mock}]\n", "robots[0] (Alice).name", "pattern"
    ),
    "robot-name-leading-digit": Bad(
        "cell: c\nrobots: [{name: 1bot, model: ur5e, backend: mock}]\n", "robots[0] (1bot).name", "pattern"
    ),
    "robot-name-dash": Bad(
        "cell: c\nrobots: [{name: left-arm, model: ur5e, backend: mock}]\n",
        "robots[0] (left-arm).name",
        "pattern",
    ),
    "robot-name-too-long": Bad(
        "cell: c\nrobots: [{name: " + "a" * 32 + ", model: ur5e, backend: mock}]\n",
        f"robots[0] ({'a' * 32}).name",
        "pattern",
    ),
    "cell-name-with-space": Bad("cell: my cell\nrobots: [" + ALICE + "}]\n", "cell", "pattern"),
    "cell-name-not-a-string": Bad("cell: 5\nrobots: [" + ALICE + "}]\n", "cell", "string"),
    # --- models and descriptions ---
    "unknown-model": Bad(
        "cell: c\nrobots: [{name: alice, model: ur7, backend: mock}]\n",
        "robots[0] (alice).model",
        "unknown model",
    ),
    "model-not-a-string": Bad(
        "cell: c\nrobots: [{name: alice, model: 5, backend: mock}]\n", "robots[0] (alice).model", "string"
    ),
    "custom-model-without-description": Bad(
        "cell: c\nrobots: [{name: alice, model: custom, backend: mock}]\n", "robots[0] (alice)", "description"
    ),
    "description-on-ur-model": Bad(
        one_robot(", description: {xacro: arm.xacro, macro: arm}"), "robots[0] (alice)", "'custom'"
    ),
    "custom-xacro-not-found": Bad(
        "cell: c\nrobots: [{name: arm, model: custom, backend: mock, "
        "description: {xacro: gone.xacro, macro: arm}}]\n",
        "robots[0] (arm).description.xacro",
        "not found",
    ),
    "custom-macro-bad-identifier": Bad(
        "cell: c\nrobots: [{name: arm, model: custom, backend: mock, "
        "description: {xacro: arm.xacro, macro: 1arm}}]\n",
        "robots[0] (arm).description.macro",
        "pattern",
    ),
    "calibration-not-found": Bad(
        one_robot(", calibration: nope/calib.yaml"), "robots[0] (alice).calibration", "not found"
    ),
    "calibration-on-custom-model": Bad(
        "cell: c\nrobots: [{name: arm, model: custom, backend: mock, calibration: calib.yaml, "
        "description: {xacro: arm.xacro, macro: arm}}]\n",
        "robots[0] (arm)",
        "UR models only",
    ),
    # --- ports ---
    "port-clash-within-robot": Bad(
        one_robot(
            ", ports: {reverse: 50001, script_sender: 50001, trajectory: 50003, script_command: 50004}"
        ),
        "robots[0] (alice).ports",
        "also the reverse port",
    ),
    "port-clash-between-robots": Bad(
        "cell: c\nrobots:\n  - "
        + ALICE
        + ", ports: "
        + PORTS_A
        + "}\n  - "
        + BOB
        + ", ports: {reverse: 50101, script_sender: 50102, trajectory: 50003, script_command: 50104}}\n",
        "robots[1] (bob).ports.trajectory",
        "clashes",
    ),
    "port-above-65535": Bad(
        one_robot(
            ", ports: {reverse: 70000, script_sender: 50002, trajectory: 50003, script_command: 50004}"
        ),
        "robots[0] (alice).ports.reverse",
        "less than or equal to 65535",
    ),
    "port-zero": Bad(
        "cell: c\nrobots:\n  - "
        + ALICE
        + "}\n  - "
        + BOB
        + ", ports: {reverse: 50101, script_sender: 0, trajectory: 50103, script_command: 50104}}\n",
        "robots[1] (bob).ports.script_sender",
        "greater than or equal to 1",
    ),
    "port-not-a-number": Bad(
        one_robot(", ports: {reverse: abc, script_sender: 50002, trajectory: 50003, script_command: 50004}"),
        "robots[0] (alice).ports.reverse",
        "integer",
    ),
    "port-missing-role": Bad(
        one_robot(", ports: {reverse: 50001, script_sender: 50002, script_command: 50004}"),
        "robots[0] (alice).ports.trajectory",
        "missing",
    ),
    # --- pose ---
    "nan-in-pose-xyz": Bad(
        one_robot(", pose: {xyz: [0, .nan, 0]}"), "robots[0] (alice).pose.xyz[1]", "finite"
    ),
    "inf-in-pose-rpy": Bad(
        one_robot(", pose: {rpy: [0, 0, -.inf]}"), "robots[0] (alice).pose.rpy[2]", "finite"
    ),
    "pose-xyz-four-values": Bad(
        one_robot(", pose: {xyz: [0, 0, 0, 0]}"), "robots[0] (alice).pose.xyz", "at most 3"
    ),
    "pose-parent-unknown-link": Bad(
        one_robot(", pose: {parent: table}"), "robots[0] (alice).pose.parent", "neither 'world'"
    ),
    "pose-parent-own-base-link": Bad(
        one_robot(", pose: {parent: alice_base_link}"), "robots[0] (alice).pose.parent", "loop"
    ),
    "pose-parent-bad-characters": Bad(
        one_robot(", pose: {parent: 'a b'}"), "robots[0] (alice).pose.parent", "pattern"
    ),
    # --- tcp ---
    "tcp-five-values": Bad(one_robot(", tcp: [0, 0, 0, 0, 0]"), "robots[0] (alice).tcp[5]", "too few"),
    "tcp-nan": Bad(one_robot(", tcp: [0, 0, .nan, 0, 0, 0]"), "robots[0] (alice).tcp[2]", "finite"),
    "tcp-too-far": Bad(one_robot(", tcp: [0, 0, 1.5, 0, 0, 0]"), "robots[0] (alice).tcp", "beyond"),
    "tcp-rotation-beyond-pi": Bad(
        one_robot(", tcp: [0, 0, 0, 3, 1, 0]"), "robots[0] (alice).tcp", "beyond pi"
    ),
    # --- mock options ---
    "initial-positions-too-short": Bad(
        one_robot(", mock: {initial_positions: [0, 0, 0]}"), "robots[0] (alice)", "3 values for 6 joints"
    ),
    "initial-positions-too-long": Bad(
        one_robot(", mock: {initial_positions: [0, 0, 0, 0, 0, 0, 0]}"),
        "robots[0] (alice)",
        "7 values for 6 joints",
    ),
    "initial-positions-unknown-joint": Bad(
        one_robot(", mock: {initial_positions: {elbow: 1.0}}"), "robots[0] (alice)", "unknown joint(s) elbow"
    ),
    "initial-positions-nan-in-dict": Bad(
        one_robot(", mock: {initial_positions: {elbow_joint: .nan}}"),
        "robots[0] (alice).mock.initial_positions.elbow_joint",
        "finite",
    ),
    "mock-speed-scaling-above-one": Bad(
        one_robot(", mock: {speed_scaling: 1.5}"),
        "robots[0] (alice).mock.speed_scaling",
        "less than or equal to 1",
    ),
    "mock-section-on-ur-backend": Bad(
        "cell: c\nrobots: [{name: alice, model: ur5e, backend: ur, address: 10.0.0.2, mock: {}}]\n",
        "robots[0] (alice)",
        "'mock' section given",
    ),
    # --- joint limits ---
    "joint-limits-unknown-joint": Bad(
        one_robot(", joint_limits: {elbow: {max_velocity: 1.0}}"),
        "robots[0] (alice)",
        "unknown joint(s) elbow",
    ),
    "joint-limits-min-above-max": Bad(
        one_robot(", joint_limits: {elbow_joint: {min_position: 1.0, max_position: -1.0}}"),
        "robots[0] (alice).joint_limits.elbow_joint",
        "must be below",
    ),
    "joint-limits-min-equals-max": Bad(
        one_robot(", joint_limits: {wrist_1_joint: {min_position: 0.5, max_position: 0.5}}"),
        "robots[0] (alice).joint_limits.wrist_1_joint",
        "must be below",
    ),
    "joint-limits-negative-velocity": Bad(
        one_robot(", joint_limits: {elbow_joint: {max_velocity: -1}}"),
        "robots[0] (alice).joint_limits.elbow_joint.max_velocity",
        "greater than 0",
    ),
    "joint-limits-inf-position": Bad(
        one_robot(", joint_limits: {elbow_joint: {max_position: .inf}}"),
        "robots[0] (alice).joint_limits.elbow_joint.max_position",
        "finite",
    ),
    # --- backends ---
    "unknown-backend": Bad(
        "cell: c\nrobots: [{name: alice, model: ur5e, backend: sim}]\n",
        "robots[0] (alice).backend",
        "'mock', 'servo' or 'ur'",
    ),
    "ur-backend-without-address": Bad(
        "cell: c\nrobots: [{name: alice, model: ur5e, backend: ur}]\n", "robots[0] (alice)", "address"
    ),
    "ur-backend-with-custom-model": Bad(
        "cell: c\nrobots: [{name: arm, model: custom, backend: ur, address: 10.0.0.2, "
        "description: {xacro: arm.xacro, macro: arm}}]\n",
        "robots[0] (arm)",
        "needs a UR model",
    ),
    "servo-backend-without-servo-section": Bad(
        "cell: c\nrobots: [{name: arm, model: custom, backend: servo, "
        "description: {xacro: arm.xacro, macro: arm}}]\n",
        "robots[0] (arm)",
        "needs a 'servo' section",
    ),
    "servo-section-on-mock-backend": Bad(
        one_robot(", servo: {joints: [{name: j1, channel: 0}]}"), "robots[0] (alice)", "'servo' section given"
    ),
    "headless-not-a-bool": Bad(one_robot(", headless: maybe"), "robots[0] (alice).headless", "boolean"),
    # --- servo options ---
    "servo-duplicate-channels": Bad(
        servo_cell("{name: j1, channel: 3}, {name: j2, channel: 3}"),
        "robots[0] (arm).servo",
        "joints j1 and j2 are both on channel 3",
    ),
    "servo-duplicate-joint-names": Bad(
        servo_cell("{name: j1, channel: 0}, {name: j1, channel: 1}"),
        "robots[0] (arm).servo",
        "duplicate joint name: j1",
    ),
    "servo-no-joints": Bad(servo_cell(""), "robots[0] (arm).servo", "at least one servo joint"),
    "servo-channel-beyond-the-boards": Bad(
        servo_cell("{name: j1, channel: 16}", ", outputs: [{kind: i2c, bus: 1, address: 0x40}]"),
        "robots[0] (arm).servo",
        "outputs[0]: a joint is on channel 16, but 1 board(s) carry channels 0–15; list the next board",
    ),
    "servo-channel-beyond-any-chain": Bad(
        servo_cell("{name: j1, channel: 1024}"),
        "robots[0] (arm).servo.joints[0] (j1).channel",
        "less than or equal to 1023",
    ),
    "servo-pulse-min-above-max": Bad(
        servo_cell("{name: j1, channel: 0, pulse_min_us: 2000, pulse_max_us: 1000}"),
        "robots[0] (arm).servo.joints[0] (j1)",
        "pulse_min_us 2000.0 must be below",
    ),
    "servo-pulse-min-equals-max": Bad(
        servo_cell("{name: j1, channel: 0, pulse_min_us: 1500, pulse_max_us: 1500}"),
        "robots[0] (arm).servo.joints[0] (j1)",
        "must be below pulse_max_us",
    ),
    "servo-angle-min-above-max": Bad(
        servo_cell("{name: j1, channel: 0, angle_min: 1, angle_max: -1}"),
        "robots[0] (arm).servo.joints[0] (j1)",
        "angle_min 1.0 must be below",
    ),
    "servo-direction-two": Bad(
        servo_cell("{name: j1, channel: 0, direction: 2}"),
        "robots[0] (arm).servo.joints[0] (j1).direction",
        "1 or -1",
    ),
    "servo-pwm-frequency-too-high": Bad(
        servo_cell("{name: j1, channel: 0}", ", pwm_frequency_hz: 2000"),
        "robots[0] (arm).servo.pwm_frequency_hz",
        "less than or equal to 1526",
    ),
    "servo-pwm-frequency-too-low": Bad(
        servo_cell("{name: j1, channel: 0}", ", pwm_frequency_hz: 20"),
        "robots[0] (arm).servo.pwm_frequency_hz",
        "greater than or equal to 24",
    ),
    "servo-pulse-longer-than-the-period": Bad(
        servo_cell("{name: j1, channel: 0, pulse_max_us: 2600}", ", pwm_frequency_hz: 400"),
        "robots[0] (arm).servo",
        "joints.j1: pulse_max_us 2600 does not fit the PWM period of 2500 µs at pwm_frequency_hz 400",
    ),
    "servo-i2c-address-too-low": Bad(
        servo_cell("{name: j1, channel: 0}", ", outputs: [{kind: i2c, address: 0x3f}]"),
        "robots[0] (arm).servo.outputs[0].i2c.address",
        "0x3f (63) is not a PCA9685 address: the A0–A5 jumpers give 0x40–0x7f",
    ),
    "servo-i2c-address-too-high": Bad(
        servo_cell("{name: j1, channel: 0}", ", outputs: [{kind: i2c, address: [0x40, 0x80]}]"),
        "robots[0] (arm).servo.outputs[0].i2c.address",
        "0x80 (128) is not a PCA9685 address",
    ),
    "servo-i2c-address-twice": Bad(
        servo_cell("{name: j1, channel: 0}", ", outputs: [{kind: i2c, address: [0x41, 0x41]}]"),
        "robots[0] (arm).servo.outputs[0].i2c",
        "address 0x41 is listed twice",
    ),
    "servo-i2c-board-in-two-outputs": Bad(
        servo_cell(
            "{name: j1, channel: 0}", ", outputs: [{kind: i2c, address: 0x40}, {kind: i2c, address: 0x40}]"
        ),
        "robots[0] (arm).servo",
        "outputs[1]: board 0x40 on bus 1 is also outputs[0]",
    ),
    "servo-i2c-oscillator-off-the-frequency": Bad(
        servo_cell(
            "{name: j1, channel: 0, pulse_max_us: 600, pulse_min_us: 550}",
            ", pwm_frequency_hz: 1526, outputs: [{kind: i2c, oscillator_hz: 21000000}]",
        ),
        "robots[0] (arm).servo",
        "outputs[0].oscillator_hz: a PCA9685 at 21 MHz makes 20.0–1281.7 Hz, not 1526 Hz",
    ),
    "servo-unknown-output-kind": Bad(
        servo_cell("{name: j1, channel: 0}", ", outputs: [{kind: spi}]"),
        "robots[0] (arm).servo.outputs[0]",
        "'zenoh', 'i2c', 'serial'",
    ),
    "servo-no-outputs": Bad(
        servo_cell("{name: j1, channel: 0}", ", outputs: []"),
        "robots[0] (arm).servo",
        "'outputs' lists nothing",
    ),
    "servo-serial-without-port": Bad(
        servo_cell("{name: j1, channel: 0}", ", outputs: [{kind: serial}]"),
        "robots[0] (arm).servo.outputs[0].serial.port",
        "missing",
    ),
    "servo-serial-port-twice": Bad(
        servo_cell(
            "{name: j1, channel: 0}",
            ", outputs: [{kind: serial, port: /dev/ttyUSB0}, {kind: serial, port: /dev/ttyUSB0}]",
        ),
        "robots[0] (arm).servo",
        "outputs[1]: port /dev/ttyUSB0 is also outputs[0]",
    ),
    "servo-serial-unknown-protocol": Bad(
        servo_cell(
            "{name: j1, channel: 0}", ", outputs: [{kind: serial, port: /dev/ttyUSB0, protocol: pololu}]"
        ),
        "robots[0] (arm).servo.outputs[0].serial.protocol",
        "'ssc32'",
    ),
    "servo-ssc32-channel-32": Bad(
        servo_cell("{name: j1, channel: 32}", ", outputs: [{kind: serial, port: /dev/ttyUSB0}]"),
        "robots[0] (arm).servo",
        "outputs[0]: a joint is on channel 32; an SSC-32 has channels 0–31",
    ),
    "servo-ssc32-pulse-range": Bad(
        servo_cell(
            "{name: j1, channel: 0, pulse_min_us: 400}", ", outputs: [{kind: serial, port: /dev/ttyUSB0}]"
        ),
        "robots[0] (arm).servo",
        "outputs[0]: joints.j1 pulses 400–2500 µs leave the 500–2500 µs an SSC-32 makes",
    ),
    "servo-unknown-safe-state": Bad(
        servo_cell("{name: j1, channel: 0}", ", safe_state: limp"),
        "robots[0] (arm).servo.safe_state",
        "'hold' or 'off'",
    ),
    # --- zenoh and publish ---
    "zenoh-client-without-connect": Bad(
        "cell: c\nzenoh: {mode: client}\nrobots: [" + ALICE + "}]\n", "zenoh", "connect endpoint"
    ),
    "zenoh-unknown-mode": Bad(
        "cell: c\nzenoh: {mode: bogus}\nrobots: [" + ALICE + "}]\n",
        "zenoh.mode",
        "'peer', 'client' or 'router'",
    ),
    "zenoh-listen-without-protocol": Bad(
        "cell: c\nzenoh: {listen: ['127.0.0.1:7447']}\nrobots: [" + ALICE + "}]\n",
        "zenoh.listen[0]",
        "pattern",
    ),
    "zenoh-listen-unknown-protocol": Bad(
        "cell: c\nzenoh: {listen: ['tcp/127.0.0.1:7447', 'http/127.0.0.1:80']}\nrobots: [" + ALICE + "}]\n",
        "zenoh.listen[1]",
        "pattern",
    ),
    "zenoh-connect-with-space": Bad(
        "cell: c\nzenoh: {mode: client, connect: ['tcp/ 10.0.0.1:7447']}\nrobots: [" + ALICE + "}]\n",
        "zenoh.connect[0]",
        "pattern",
    ),
    "zenoh-connect-empty-address": Bad(
        "cell: c\nzenoh: {connect: ['tcp/']}\nrobots: [" + ALICE + "}]\n", "zenoh.connect[0]", "pattern"
    ),
    "publish-zero-rate": Bad(
        "cell: c\npublish: {tf_rate_hz: 0}\nrobots: [" + ALICE + "}]\n",
        "publish.tf_rate_hz",
        "greater than or equal to 1",
    ),
    "publish-decimation-zero": Bad(
        "cell: c\npublish: {joint_states_decimation: 0}\nrobots: [" + ALICE + "}]\n",
        "publish.joint_states_decimation",
        "greater than or equal to 1",
    ),
    "motion-stream-timeout-too-long": Bad(
        one_robot(", motion: {stream_timeout: 11}"),
        "robots[0] (alice).motion.stream_timeout",
        "less than or equal to 10",
    ),
}


@pytest.fixture
def cell_dir(tmp_path: Path) -> Path:
    """A folder holding the files some cases refer to (an xacro and a calibration file)."""
    (tmp_path / "arm.xacro").write_text("<robot xmlns:xacro='http://www.ros.org/wiki/xacro'/>\n")
    (tmp_path / "calib.yaml").write_text("kinematics: {}\n")
    return tmp_path


def load_bad(folder: Path, text: str) -> tuple[Path, ConfigError]:
    """Write ``text`` as a cell file in ``folder`` and return the error loading it raises."""
    path = folder / "cell.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_cell(path)
    return path, info.value


def test_there_are_many_bad_cases() -> None:
    assert len(BAD_CELLS) >= 30


@pytest.mark.parametrize("case", list(BAD_CELLS.values()), ids=list(BAD_CELLS))
def test_bad_cell_names_file_key_path_and_reason(cell_dir: Path, case: Bad) -> None:
    path, err = load_bad(cell_dir, case.text)
    prefix = f"{path}: {case.path}: "
    matching = [line for line in err.errors if line.startswith(prefix)]
    assert matching, f"no error line starts with {prefix!r}: {err.errors}"
    assert any(case.reason.lower() in line.lower() for line in matching), err.errors
    # the exception message carries every error line
    message = str(err)
    assert all(line in message for line in err.errors)
    assert message.splitlines() == err.errors


def test_error_lines_name_the_file_given_to_parse_cell() -> None:
    with pytest.raises(ConfigError) as info:
        parse_cell("cell: c\nrobots: [{name: alice, model: ur7, backend: mock}]\n", source="my/cell.yaml")
    assert info.value.errors == [
        "my/cell.yaml: robots[0] (alice).model: unknown model 'ur7'; known: "
        "ur10, ur10e, ur16e, ur20, ur3, ur30, ur3e, ur5, ur5e, or 'custom'"
    ]


def test_parse_cell_default_source_is_string_marker() -> None:
    with pytest.raises(ConfigError) as info:
        parse_cell("cell: c\n")
    assert info.value.errors == ["<string>: robots: required key is missing"]


def test_every_problem_is_reported_not_just_the_first(cell_dir: Path) -> None:
    text = (
        "cell: c\nzenoh: {mode: bogus}\nrobots:\n"
        "  - {name: alice, model: ur7, backend: mock}\n"
        "  - {name: bob, model: ur5e, backend: mock, ports: {reverse: 70000, script_sender: 2, "
        "trajectory: 3, script_command: 4}}\n"
    )
    path, err = load_bad(cell_dir, text)
    paths = [line.removeprefix(f"{path}: ").split(": ", 1)[0] for line in err.errors]
    assert paths == ["zenoh.mode", "robots[0] (alice).model", "robots[1] (bob).ports.reverse"]


def test_error_key_path_of_robot_without_name_has_no_label(cell_dir: Path) -> None:
    path, err = load_bad(cell_dir, "cell: c\nrobots: [{model: ur5e, backend: mock}]\n")
    assert f"{path}: robots[0].name: required key is missing" in err.errors


def test_top_level_integer_key_is_refused(cell_dir: Path) -> None:
    path, err = load_bad(cell_dir, "1: x\ncell: c\nrobots: [" + ALICE + "}]\n")
    assert any(line.startswith(f"{path}: [1]: ") for line in err.errors), err.errors


# --- the file itself ---


def test_invalid_yaml_names_line_and_column(tmp_path: Path) -> None:
    path, err = load_bad(tmp_path, "cell: c\nrobots:\n  - {name: alice, model: ur5e\n  backend: mock\n")
    (line,) = err.errors
    assert line.startswith(f"{path} (line ")
    assert "column" in line
    assert "not valid YAML" in line


def test_invalid_yaml_line_and_column_are_one_based(tmp_path: Path) -> None:
    # the indented mapping under the scalar 'c' is not YAML; PyYAML's 0-based mark is line 1 col 8
    path, err = load_bad(tmp_path, "cell: c\n  robots: x\n")
    assert err.errors == [f"{path} (line 2, column 9): not valid YAML: mapping values are not allowed here"]


def test_yaml_tab_indentation_is_refused_with_position(tmp_path: Path) -> None:
    path, err = load_bad(tmp_path, "cell: c\nrobots:\n\t- {name: alice}\n")
    (line,) = err.errors
    assert line.startswith(f"{path} (line 3, column 1): not valid YAML")


def test_python_object_tags_are_refused(tmp_path: Path) -> None:
    path, err = load_bad(tmp_path, "cell: !!python/object/apply:os.system ['true']\nrobots: []\n")
    assert str(err).startswith(f"{path} (line 1, column ")
    assert "not valid YAML" in str(err)


@pytest.mark.parametrize(
    ("text", "kind"),
    [
        ("- cell: c\n- robots: []\n", "list"),
        ("just a string\n", "str"),
        ("42\n", "int"),
        ("3.5\n", "float"),
        ("true\n", "bool"),
        ("", "NoneType"),
        ("# only a comment\n", "NoneType"),
    ],
)
def test_cell_file_must_be_a_mapping(tmp_path: Path, text: str, kind: str) -> None:
    path, err = load_bad(tmp_path, text)
    assert err.errors == [f"{path}: the cell file must be a mapping with 'cell' and 'robots', got {kind}"]


def test_missing_file_is_a_config_error(tmp_path: Path) -> None:
    path = tmp_path / "nope.yaml"
    with pytest.raises(ConfigError) as info:
        load_cell(path)
    assert str(info.value).startswith(f"{path}: cannot read")
    assert "No such file" in str(info.value)


def test_directory_instead_of_file_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as info:
        load_cell(tmp_path)
    assert str(info.value).startswith(f"{tmp_path}: cannot read")


def test_config_error_is_a_value_error() -> None:
    with pytest.raises(ValueError, match="required key is missing"):
        parse_cell("cell: c\n")


def test_non_utf8_file_is_a_config_error(tmp_path: Path) -> None:
    path = tmp_path / "cell.yaml"
    path.write_bytes(b"cell: caf\xe9\nrobots: []\n")
    with pytest.raises(ConfigError) as info:
        load_cell(path)
    assert str(info.value).startswith(str(path))


@pytest.mark.parametrize(
    "text",
    [
        "cell: c\ncell: d\nrobots: [" + ALICE + "}]\n",
        "cell: c\nrobots: [" + ALICE + ", backend: ur, address: 10.0.0.2}]\n",
    ],
    ids=["top-level", "robot"],
)
def test_duplicate_yaml_keys_are_refused(tmp_path: Path, text: str) -> None:
    _, err = load_bad(tmp_path, text)
    assert any("duplicate" in line for line in err.errors), err.errors


def test_nan_in_initial_positions_list_has_a_clean_key_path(tmp_path: Path) -> None:
    path, err = load_bad(
        tmp_path, "cell: c\nrobots: [" + ALICE + ", mock: {initial_positions: [0, 0, .nan, 0, 0, 0]}}]\n"
    )
    assert any(
        line.startswith(f"{path}: robots[0] (alice).mock.initial_positions[2]: ") and "finite" in line
        for line in err.errors
    ), err.errors
    assert not any("tuple[" in line or "dict[" in line for line in err.errors), err.errors


def test_nan_in_initial_positions_list_is_refused(tmp_path: Path) -> None:
    """The refusal itself names the list."""
    path, err = load_bad(
        tmp_path, "cell: c\nrobots: [" + ALICE + ", mock: {initial_positions: [0, 0, .nan, 0, 0, 0]}}]\n"
    )
    assert any(
        line.startswith(f"{path}: robots[0] (alice).mock.initial_positions") and "finite" in line
        for line in err.errors
    ), err.errors


@pytest.mark.parametrize(
    ("text", "key_path"),
    [
        ("cell: c\nrobots: []\n", "robots"),
        ("cell: c\nrobots: [" + ALICE + "}, " + ALICE + "}]\n", "robots[1] (alice).name"),
        (
            "cell: c\nrobots:\n  - "
            + ALICE
            + ", ports: "
            + PORTS_A
            + "}\n  - "
            + BOB
            + ", ports: {reverse: 50101, script_sender: 50102, trajectory: 50003, script_command: 50104}}\n",
            "robots[1] (bob).ports.trajectory",
        ),
        (one_robot(", pose: {parent: table}"), "robots[0] (alice).pose.parent"),
    ],
    ids=["empty-robots", "duplicate-name", "port-clash-between-robots", "unknown-parent"],
)
def test_cell_level_problems_name_the_key_path(tmp_path: Path, text: str, key_path: str) -> None:
    path, err = load_bad(tmp_path, text)
    assert any(line.startswith(f"{path}: {key_path}: ") for line in err.errors), err.errors


def test_port_clash_between_robots_names_both_robots_and_the_port(tmp_path: Path) -> None:
    text = (
        "cell: c\nrobots:\n  - "
        + ALICE
        + ", ports: "
        + PORTS_A
        + "}\n  - "
        + BOB
        + ", ports: {reverse: 50101, script_sender: 50102, trajectory: 50003, script_command: 50104}}\n"
    )
    path, err = load_bad(tmp_path, text)
    assert err.errors == [
        f"{path}: robots[1] (bob).ports.trajectory: "
        "robot 'bob' trajectory port 50003 clashes with robot 'alice' trajectory port"
    ]


@pytest.mark.parametrize(
    "text",
    [
        one_robot(", pose: {parent: alice_tool0}"),
        "cell: c\nrobots: ["
        + ALICE
        + ", pose: {parent: bob_tool0}}, "
        + BOB
        + ", pose: {parent: alice_tool0}}]\n",
    ],
    ids=["own-tool0", "two-robot-loop"],
)
def test_kinematic_loops_are_refused(tmp_path: Path, text: str) -> None:
    _, err = load_bad(tmp_path, text)
    assert any("parent" in line for line in err.errors), err.errors
