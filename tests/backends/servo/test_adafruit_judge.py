"""Adafruit's PCA9685 driver as an independent judge of ours: for the same joint angles, boards driven
by our mapping and Pca9685Link and boards driven by ``adafruit_pca9685`` must end with the same
registers (MODE1, MODE2, PRE_SCALE and every LED register), both without a datasheet violation.

The judge's side shares none of our code: the pulse comes from this file's own linear formula over
the ServoJoint fields and the count from Adafruit's own (read back) frequency, as its documentation
has users do. Both sides drive tests/boards/pca9685_model.py boards, Adafruit's through a busio.I2C
shaped adapter."""

from __future__ import annotations

import math
from collections.abc import Sequence
from types import SimpleNamespace
from typing import Any
from unittest import mock

import adafruit_pca9685
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.boards.pca9685_model import BusioI2C, FakeSmbus, ModelClock
from urdaemon.backends.servo.i2c_link import Pca9685Link
from urdaemon.backends.servo.mapping import ServoMapping
from urdaemon.cell.servo import I2cOutput, ServoJoint, ServoOptions

PREFIX = "arm_"


def judge_pulse_us(joint: ServoJoint, angle: float) -> float:
    """The joint's pulse at ``angle``: linear from (angle_min, pulse_min) to (angle_max, pulse_max)
    after direction and offset, held at the ends."""
    turned = joint.direction * angle + joint.offset
    share = min(max((turned - joint.angle_min) / (joint.angle_max - joint.angle_min), 0.0), 1.0)
    return joint.pulse_min_us + share * (joint.pulse_max_us - joint.pulse_min_us)


class Arm:
    """One arm's joints driven twice: boards on our link, boards on Adafruit's driver."""

    def __init__(
        self,
        joints: Sequence[ServoJoint],
        frequency_hz: float,
        oscillator_hz: int,
        addresses: tuple[int, ...],
    ) -> None:
        self.joints = list(joints)
        self.addresses = addresses
        self.names = [f"{PREFIX}{j.name}" for j in joints]
        output = I2cOutput(kind="i2c", address=addresses, oscillator_hz=oscillator_hz)
        options = ServoOptions(pwm_frequency_hz=frequency_hz, joints=tuple(joints), outputs=(output,))
        self.mapping = ServoMapping(self.names, PREFIX, options)
        self.clock = ModelClock()
        self.ours = FakeSmbus.with_boards(addresses, self.clock, oscillator_hz)
        self.link = Pca9685Link(
            output, frequency_hz, self.mapping.channels, open_bus=self.ours.open, sleep=self.clock.advance
        )
        self.link.open()
        self.theirs = FakeSmbus.with_boards(addresses, self.clock, oscillator_hz)
        adapter = BusioI2C(self.theirs)
        with mock.patch.object(adafruit_pca9685, "time", SimpleNamespace(sleep=self.clock.advance)):
            self.pcas = [
                adafruit_pca9685.PCA9685(adapter, address=a, reference_clock_speed=oscillator_hz)
                for a in addresses
            ]
            for pca in self.pcas:
                pca.frequency = frequency_hz

    def move(self, angles: Sequence[float]) -> None:
        """Both sides put the joints at ``angles`` (one per joint, description order = joint order)."""
        self.link.write(self.mapping.update(angles))
        for joint, angle in zip(self.joints, angles, strict=True):
            board, pin = divmod(joint.channel, 16)
            pca = self.pcas[board]
            count = round(judge_pulse_us(joint, angle) * 1e-6 * pca.frequency * 4096)
            pca.channels[pin].duty_cycle = count << 4

    def assert_same_boards(self) -> None:
        """Both sides' boards hold the same registers and make the same pulses, without violations."""
        for address, ours in self.ours.boards.items():
            theirs = self.theirs.boards[address]
            for register in (0x00, 0x01, 0xFE):
                assert ours.register(register) == theirs.register(register), (hex(address), hex(register))
            assert ours.led_registers.hex(" ", 4) == theirs.led_registers.hex(" ", 4), hex(address)
            assert [ours.pulse_us(c) for c in range(16)] == [theirs.pulse_us(c) for c in range(16)]
            assert (ours.violations, theirs.violations) == ([], [])

    def assert_pulses_within_half_a_count(self, angles: Sequence[float]) -> None:
        """The pulse each board makes is the judge's pulse for the angle, within half a count."""
        for joint, angle in zip(self.joints, angles, strict=True):
            board = self.ours.boards[self.addresses[joint.channel // 16]]
            made = board.pulse_us(joint.channel % 16)
            assert abs(made - judge_pulse_us(joint, angle)) <= board.period_us / 4096 / 2 + 1e-6, joint.name


def servo(name: str, channel: int, **fields: Any) -> ServoJoint:
    return ServoJoint(name=name, channel=channel, **fields)


SIX = [servo(f"j{k}", k) for k in range(6)]
ANGLE_SETS = [
    [0.0] * 6,
    [-math.pi / 2, -1.0, -0.25, 0.25, 1.0, math.pi / 2],
    [3.0, -3.0, 0.1234, -0.987, 1.5, -1.5],  # beyond the joint range: held at the pulse limits
]


@pytest.mark.parametrize(
    ("frequency_hz", "oscillator_hz"),
    [(50.0, 25_000_000), (330.0, 25_000_000), (50.0, 26_600_000), (60.0, 23_700_000), (200.0, 25_000_000)],
)
def test_six_servos_on_one_board_agree_with_adafruit(frequency_hz: float, oscillator_hz: int) -> None:
    arm = Arm(SIX, frequency_hz, oscillator_hz, (0x40,))
    arm.assert_same_boards()  # after start-up alone
    for angles in ANGLE_SETS:
        arm.move(angles)
        arm.assert_same_boards()
        arm.assert_pulses_within_half_a_count(angles)


def test_chained_boards_agree_with_adafruit() -> None:
    joints = [
        servo("base", 3, pulse_min_us=600.0, pulse_max_us=2400.0, offset=0.2),
        servo(
            "wrist", 17, pulse_min_us=1000.0, pulse_max_us=2000.0, angle_min=-1.0, angle_max=1.0, direction=-1
        ),
    ]
    arm = Arm(joints, 50.0, 25_000_000, (0x40, 0x41))
    for angles in ([0.0, 0.0], [0.7, -0.4], [-2.0, 2.0]):
        arm.move(angles)
        arm.assert_same_boards()
        arm.assert_pulses_within_half_a_count(angles)
    assert arm.theirs.boards[0x41].channels()[1].off == arm.ours.boards[0x41].channels()[1].off == 205


@st.composite
def arms(draw: st.DrawFn) -> tuple[list[ServoJoint], float, int, tuple[int, ...]]:
    """An arm of 1..6 servos on one or two boards with realistic pulses, a frequency and an oscillator."""
    boards = draw(st.sampled_from([(0x40,), (0x40, 0x41), (0x45, 0x7F)]))
    channels = draw(st.lists(st.integers(0, 16 * len(boards) - 1), min_size=1, max_size=6, unique=True))
    joints = [
        ServoJoint(
            name=f"j{k}",
            channel=channel,
            pulse_min_us=draw(st.floats(400.0, 1000.0)),
            pulse_max_us=draw(st.floats(1800.0, 2500.0)),
            angle_min=draw(st.floats(-2.0, -0.5)),
            angle_max=draw(st.floats(0.5, 2.0)),
            offset=draw(st.floats(-0.3, 0.3)),
            direction=draw(st.sampled_from([1, -1])),
        )
        for k, channel in enumerate(channels)
    ]
    frequency_hz = draw(st.floats(40.0, 380.0))  # 2500 µs fits the period
    oscillator_hz = draw(st.integers(23_000_000, 27_000_000))
    return joints, frequency_hz, oscillator_hz, boards


@settings(max_examples=15, deadline=None)
@given(arm_spec=arms(), data=st.data())
def test_random_arms_agree_with_adafruit(
    arm_spec: tuple[list[ServoJoint], float, int, tuple[int, ...]], data: st.DataObject
) -> None:
    joints, frequency_hz, oscillator_hz, addresses = arm_spec
    arm = Arm(joints, frequency_hz, oscillator_hz, addresses)
    for _ in range(3):
        angles = data.draw(st.lists(st.floats(-2.5, 2.5), min_size=len(joints), max_size=len(joints)))
        arm.move(angles)
        arm.assert_same_boards()
        arm.assert_pulses_within_half_a_count(angles)


def test_a_pulse_under_half_a_count_agrees_with_adafruit() -> None:
    arm = Arm([servo("tiny", 0, pulse_min_us=1.0, pulse_max_us=2000.0)], 50.0, 25_000_000, (0x40,))
    arm.move([-math.pi / 2])  # 1 µs: 0.2 counts
    arm.assert_same_boards()
