"""The servo backend: joint angle → pulse width → PCA9685 count, published as 16 channel values each cycle."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from urdaemon.backends import ServoBackend, ServoMapping
from urdaemon.cell import load_cell
from urdaemon.cell.servo import ServoJoint, ServoOptions
from urdaemon.errors import BackendError, ConfigError
from urdaemon.model import CommandMode

SERVO = Path(__file__).resolve().parents[2] / "configs" / "servo_arm.yaml"


def options(*joints: ServoJoint, freq: float = 50.0, rate: float = 50.0) -> ServoOptions:
    return ServoOptions(pwm_frequency_hz=freq, rate_hz=rate, joints=joints)


def joint(name: str = "j", channel: int = 0, **kw: Any) -> ServoJoint:
    return ServoJoint(name=name, channel=channel, **kw)


def counts(pulse_us: float, freq: float = 50.0) -> int:
    """The PCA9685 off-count for a pulse, as the datasheet defines it: the prescale the frequency gives
    with the 25 MHz oscillator (eq. 1), then the pulse's share of the period that prescale makes."""
    prescale = math.floor(25e6 / (4096 * freq) + 0.5) - 1
    return min(max(math.floor(pulse_us * 25e6 / ((prescale + 1) * 1e6) + 0.5), 0), 4095)


# --- ServoMapping.pulse_us ---


def test_pulse_at_angle_min_mid_and_max() -> None:
    mapping = ServoMapping(
        ("p_j",), "p_", options(joint(angle_min=-1.0, angle_max=1.0, pulse_min_us=1000, pulse_max_us=2000))
    )
    assert mapping.pulse_us(0, -1.0) == 1000.0
    assert mapping.pulse_us(0, 0.0) == 1500.0
    assert mapping.pulse_us(0, 1.0) == 2000.0
    assert mapping.pulse_us(0, 0.5) == 1750.0


def test_default_joint_maps_half_pi_span_to_500_2500() -> None:
    mapping = ServoMapping(("p_j",), "p_", options(joint()))
    assert mapping.pulse_us(0, -math.pi / 2) == pytest.approx(500.0)
    assert mapping.pulse_us(0, 0.0) == pytest.approx(1500.0)
    assert mapping.pulse_us(0, math.pi / 2) == pytest.approx(2500.0)


def test_direction_minus_one_mirrors_the_mapping() -> None:
    mapping = ServoMapping(
        ("p_j",),
        "p_",
        options(joint(angle_min=-1.0, angle_max=1.0, pulse_min_us=1000, pulse_max_us=2000, direction=-1)),
    )
    assert mapping.pulse_us(0, -1.0) == 2000.0
    assert mapping.pulse_us(0, 1.0) == 1000.0
    assert mapping.pulse_us(0, 0.0) == 1500.0
    assert mapping.pulse_us(0, 0.5) == 1250.0


def test_offset_is_added_to_the_angle() -> None:
    mapping = ServoMapping(
        ("p_j",),
        "p_",
        options(joint(angle_min=-1.0, angle_max=1.0, pulse_min_us=1000, pulse_max_us=2000, offset=0.5)),
    )
    assert mapping.pulse_us(0, 0.0) == 1750.0
    assert mapping.pulse_us(0, -1.5) == 1000.0
    assert mapping.pulse_us(0, 0.5) == 2000.0


def test_offset_with_direction_minus_one() -> None:
    mapping = ServoMapping(
        ("p_j",),
        "p_",
        options(
            joint(
                angle_min=-1.0, angle_max=1.0, pulse_min_us=1000, pulse_max_us=2000, offset=0.5, direction=-1
            )
        ),
    )
    # servo angle = direction × position + offset
    assert mapping.pulse_us(0, 0.0) == 1750.0
    assert mapping.pulse_us(0, 0.5) == 1500.0
    assert mapping.pulse_us(0, 1.5) == 1000.0


@pytest.mark.parametrize(
    ("position", "pulse"),
    [
        (-5.0, 1000.0),
        (-1.0001, 1000.0),
        (1.0001, 2000.0),
        (5.0, 2000.0),
        (math.inf, 2000.0),
        (-math.inf, 1000.0),
    ],
)
def test_pulse_is_clamped_to_the_range(position: float, pulse: float) -> None:
    mapping = ServoMapping(
        ("p_j",), "p_", options(joint(angle_min=-1.0, angle_max=1.0, pulse_min_us=1000, pulse_max_us=2000))
    )
    assert mapping.pulse_us(0, position) == pulse


# --- ServoMapping.update: pulses ---


def test_update_gives_each_configured_joint_its_pulse_in_the_cell_files_order() -> None:
    mapping = ServoMapping(
        ("p_a", "p_b"),
        "p_",
        options(
            joint("b", 15, angle_min=-1, angle_max=1, pulse_min_us=1000, pulse_max_us=2000),
            joint("a", 4, angle_min=-1, angle_max=1, pulse_min_us=1000, pulse_max_us=2000),
        ),
    )
    pulses = mapping.update([1.0, -1.0])  # a = 1.0 (max), b = -1.0 (min)
    assert pulses == [1000.0, 2000.0]  # b first, as listed
    assert mapping.channels == (15, 4)


def test_update_recomputes_in_place() -> None:
    mapping = ServoMapping(
        ("p_j",), "p_", options(joint(angle_min=-1, angle_max=1, pulse_min_us=1000, pulse_max_us=2000))
    )
    first = mapping.update([-1.0])
    assert first == [1000.0]
    second = mapping.update([1.0])
    assert second is first
    assert second == [2000.0]


def test_unknown_servo_joint_is_a_config_error() -> None:
    said = r"servo\.joints: elbow, zz not in the robot's description \(its joints: a\)"
    with pytest.raises(ConfigError, match=said):
        ServoMapping(("p_a",), "p_", options(joint("a", 0), joint("zz", 1), joint("elbow", 2)))


def test_servo_joint_needs_the_prefix() -> None:
    with pytest.raises(ConfigError, match=r"servo\.joints: a not in the robot's description"):
        ServoMapping(("a",), "p_", options(joint("a", 0)))


@pytest.mark.parametrize(
    ("lows", "highs", "offset", "direction", "refused"),
    [
        ([-1.0], [1.0], 0.0, 1, False),  # the servo's range exactly
        ([-0.5], [0.5], 0.4, 1, False),
        ([-1.0], [1.0], 0.1, 1, True),  # the offset takes the servo past angle_max
        ([-1.0], [0.8], 0.2, -1, True),  # mirrored: -(-1.0) + 0.2 = 1.2
        ([-0.8], [1.0], 0.2, -1, False),  # mirrored: [-0.8, 1.0] → [-0.8, 1.0]
        ([-1.2], [0.5], 0.0, 1, True),
    ],
)
def test_joint_limits_the_servo_cannot_follow_are_named(
    lows: list[float], highs: list[float], offset: float, direction: int, refused: bool
) -> None:
    servo = joint(angle_min=-1.0, angle_max=1.0, offset=offset, direction=direction)
    problems = ServoMapping(("p_j",), "p_", options(servo)).uncovered(lows, highs)
    assert bool(problems) is refused
    if refused:
        assert problems[0].startswith("servo.joints (j): the joint's limits")
        assert "narrow the limits (joint_limits.j) or widen the servo's angle range" in problems[0]


def test_description_joints_without_a_servo_channel_are_refused() -> None:
    with pytest.raises(ConfigError, match=r"the description's joint\(s\) a have no servo channel"):
        ServoMapping(("p_a", "p_b"), "p_", options(joint("b", 3)))


@pytest.mark.parametrize(("freq", "pulse"), [(400.0, 2500.0), (1526.0, 2500.0), (1000.0, 1000.0)])
def test_a_pulse_longer_than_the_pwm_period_is_refused(freq: float, pulse: float) -> None:
    with pytest.raises(ValidationError, match=f"pulse_max_us {pulse:g} does not fit the PWM period"):
        options(joint(pulse_min_us=pulse - 100, pulse_max_us=pulse), freq=freq)


@st.composite
def servo_joints(draw: st.DrawFn) -> ServoJoint:
    angle_min = draw(st.floats(min_value=-4.0, max_value=3.9))
    angle_max = draw(st.floats(min_value=angle_min + 0.01, max_value=4.0))
    pulse_min = draw(st.floats(min_value=1.0, max_value=19000.0))
    pulse_max = draw(st.floats(min_value=pulse_min + 1.0, max_value=19999.0))
    return ServoJoint(
        name="j",
        channel=draw(st.integers(min_value=0, max_value=15)),
        pulse_min_us=pulse_min,
        pulse_max_us=pulse_max,
        angle_min=angle_min,
        angle_max=angle_max,
        offset=draw(st.floats(min_value=-1.0, max_value=1.0)),
        direction=draw(st.sampled_from([1, -1])),
    )


@settings(max_examples=300, deadline=None)
@given(
    servo=servo_joints(),
    freq=st.floats(min_value=24.0, max_value=1526.0),
    a=st.floats(min_value=-10.0, max_value=10.0),
    b=st.floats(min_value=-10.0, max_value=10.0),
)
def test_mapping_properties(servo: ServoJoint, freq: float, a: float, b: float) -> None:
    assume(servo.pulse_max_us < 1e6 / freq)
    mapping = ServoMapping(("p_j",), "p_", options(servo, freq=freq))
    pa, pb = mapping.pulse_us(0, a), mapping.pulse_us(0, b)
    for pulse in (pa, pb):
        assert servo.pulse_min_us - 1e-9 <= pulse <= servo.pulse_max_us + 1e-9
    lo, hi = (pa, pb) if a <= b else (pb, pa)
    if servo.direction == 1:
        assert lo <= hi + 1e-9
    else:
        assert lo >= hi - 1e-9
    assert mapping.update([a]) == [pa]


def test_a_nan_position_keeps_the_last_pulse() -> None:
    mapping = ServoMapping(("p_j",), "p_", options(joint()))
    assert mapping.update([0.5]) == [mapping.pulse_us(0, 0.5)]
    assert mapping.update([math.nan]) == [mapping.pulse_us(0, 0.5)]


# --- ServoBackend ---


def servo_arm() -> tuple[ServoBackend, list[bytes]]:
    cell = load_cell(SERVO)
    robot = cell.robots[0]
    assert robot.servo is not None
    names = tuple(f"{robot.prefix}{j.name}" for j in robot.servo.joints)
    published: list[bytes] = []
    backend = ServoBackend(robot.name, names, robot.prefix, robot.servo, publish=published.append)
    return backend, published


def test_servo_backend_takes_its_rate_from_the_options() -> None:
    backend, _ = servo_arm()
    assert backend.kind == "servo"
    assert backend.rate_hz == 50.0
    assert backend.period == 0.02


def test_servo_backend_publishes_16_ints_each_step() -> None:
    backend, published = servo_arm()
    assert published == []
    backend.command.mode = CommandMode.POSITION
    backend.command.positions[:] = [0.0, 0.0, 0.0, 0.0]
    backend.step()
    assert len(published) == 1
    message = json.loads(published[0])
    assert list(message) == [
        "v",
        "robot",
        "pwm_frequency_hz",
        "host_time_ns",
        "controller_time",
        "channels",
        "pulses_us",
    ]
    assert (message["host_time_ns"], message["controller_time"]) == (
        backend.state.host_time_ns,
        backend.state.controller_time,
    )
    assert message["v"] == 1
    assert message["robot"] == "arm"
    assert message["pwm_frequency_hz"] == 50.0
    channels = message["channels"]
    assert len(channels) == 16
    assert all(type(c) is int and 0 <= c <= 4095 for c in channels)
    # base_yaw, shoulder, elbow at their mid pulse; wrist has offset 0.1 rad
    assert channels[0] == counts(1500.0)
    assert channels[1] == counts(1500.0)
    assert channels[2] == counts(1500.0)
    assert channels[3] == counts(1500.0 + 0.1 / 3.1416 * 2000.0)
    assert channels[4:] == [0] * 12
    assert message["pulses_us"][:3] == [1500.0] * 3
    assert message["pulses_us"][3] == pytest.approx(1500.0 + 0.1 / 1.5708 * 1000.0, abs=0.05)
    assert message["pulses_us"][4:] == [0.0] * 12
    backend.step()
    assert len(published) == 2


def test_servo_backend_maps_the_mirrored_position() -> None:
    backend, published = servo_arm()
    backend.command.mode = CommandMode.POSITION
    backend.command.positions[:] = [1.5708, 1.5708, -2.0, -1.5708]
    backend.step()
    assert backend.state.positions == [1.5708, 1.5708, -2.0, -1.5708]
    channels = json.loads(published[-1])["channels"]
    assert channels[0] == counts(2500.0)  # base_yaw at angle_max
    assert channels[1] == counts(500.0)  # shoulder, direction -1
    assert channels[2] == counts(600.0)  # elbow at its angle_min
    assert channels[3] == counts(500.0 + 0.1 / 3.1416 * 2000.0)  # wrist: -1.5708 + 0.1 offset
    assert backend.mapping.pulses == [2500.0, 500.0, 600.0, pytest.approx(500.0 + 0.1 / 3.1416 * 2000.0)]


def test_servo_backend_velocity_mode_is_integrated_then_mapped() -> None:
    backend, published = servo_arm()
    backend.command.mode = CommandMode.VELOCITY
    backend.command.velocities[:] = [1.0, 0.0, 0.0, 0.0]
    for _ in range(10):
        backend.step()
    assert backend.state.positions[0] == pytest.approx(0.2)
    assert json.loads(published[-1])["channels"][0] == counts(
        1500.0 + backend.state.positions[0] / 3.1416 * 2000.0
    )


def test_servo_backend_without_publisher_still_steps() -> None:
    cell = load_cell(SERVO)
    robot = cell.robots[0]
    assert robot.servo is not None
    names = tuple(f"{robot.prefix}{j.name}" for j in robot.servo.joints)
    backend = ServoBackend("arm", names, robot.prefix, robot.servo, initial_positions=[0.5, 0.0, 0.0, 0.0])
    backend.step()
    assert backend.state.cycle == 1
    assert backend.state.positions == [0.5, 0.0, 0.0, 0.0]
    assert backend.mapping.pulses[0] == pytest.approx(1500.0 + 0.5 / (math.pi / 2) * 1000.0)


def test_servo_backend_refuses_unknown_servo_joint() -> None:
    cell = load_cell(SERVO)
    robot = cell.robots[0]
    assert robot.servo is not None
    with pytest.raises(ConfigError, match=r"servo\.joints: wrist not in the robot's description"):
        ServoBackend("arm", ("arm_base_yaw", "arm_shoulder", "arm_elbow"), robot.prefix, robot.servo)


async def test_servo_backend_has_no_io_or_payload() -> None:
    backend, _ = servo_arm()
    with pytest.raises(BackendError, match="servo backend has no IO outputs"):
        await backend.set_io("digital", 0, True)
    with pytest.raises(BackendError, match="servo backend has no payload setting"):
        await backend.set_payload(1.0, (0.0, 0.0, 0.0))


async def test_servo_backend_speed_slider() -> None:
    backend, _ = servo_arm()
    await backend.set_speed_slider(0.5)
    backend.step()
    assert backend.state.speed_scaling == 0.5


def test_servo_backend_robot_name_is_json_escaped() -> None:
    published: list[bytes] = []
    backend = ServoBackend('a"b', ("p_j",), "p_", options(joint()), publish=published.append)
    backend.step()
    assert json.loads(published[0])["robot"] == 'a"b'
