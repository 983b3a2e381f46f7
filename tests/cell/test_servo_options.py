"""The servo section's cross-checks that depend on the outputs (the bad cases are in
test_cell_errors.py's table; these are the ones that must pass, and the wording of chained boards)."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from urdaemon.cell.servo import ServoOptions


def servo(outputs: list[dict[str, object]], **extra: object) -> ServoOptions:
    joints = [{"name": "a", "channel": 0}, {"name": "b", "channel": 17}]
    return ServoOptions.model_validate({"joints": joints, "outputs": outputs, **extra})


def test_a_serial_only_arm_is_not_held_to_the_pca9685_period() -> None:
    options = servo([{"kind": "serial", "port": "/dev/ttyUSB0"}], pwm_frequency_hz=1000)
    assert options.publishes is False


def test_the_period_still_counts_when_the_pulses_are_also_published() -> None:
    with pytest.raises(ValidationError, match="does not fit the PWM period of 1000 µs"):
        servo([{"kind": "serial", "port": "/dev/ttyUSB0"}, {"kind": "zenoh"}], pwm_frequency_hz=1000)


def test_a_chain_carries_channels_across_its_boards() -> None:
    options = servo([{"kind": "i2c", "address": [0x40, 0x41]}])
    assert options.outputs[0].kind == "i2c"
    assert options.publishes is False


def test_a_shared_channel_on_a_later_board_names_its_pin() -> None:
    joints = [{"name": "a", "channel": 17}, {"name": "b", "channel": 17}]
    with pytest.raises(ValidationError, match=r"both on channel 17 \(pin 1 of board 1 of an i2c chain"):
        ServoOptions.model_validate({"joints": joints})


def test_the_default_output_publishes() -> None:
    options = ServoOptions.model_validate({"joints": [{"name": "a", "channel": 0}]})
    assert [o.kind for o in options.outputs] == ["zenoh"]
    assert options.publishes
    assert options.safe_state == "hold"
