"""A servo arm's outputs as its cell file lists them: the device links the backend drives, and what
``urdaemon check`` and ``serve`` refuse before starting (a device file that is missing or that this
user may not open)."""

from __future__ import annotations

import os
from collections.abc import Callable

from urdaemon.backends.servo.i2c_link import Pca9685Link
from urdaemon.backends.servo.link import BoardLink
from urdaemon.backends.servo.serial_link import Ssc32Link
from urdaemon.cell.servo import I2cOutput, SerialOutput, ServoOptions

__all__ = ["board_links", "device_problems"]


def board_links(options: ServoOptions) -> list[BoardLink]:
    """A link per device output (``i2c``, ``serial``), on the real devices; ``zenoh`` has none."""
    channels = [j.channel for j in options.joints]
    links: list[BoardLink] = []
    for output in options.outputs:
        if isinstance(output, I2cOutput):
            links.append(Pca9685Link(output, options.pwm_frequency_hz, channels))
        elif isinstance(output, SerialOutput):
            links.append(Ssc32Link(output, channels))
    return links


def device_problems(
    options: ServoOptions,
    where: str,
    *,
    exists: Callable[[str], bool] = os.path.exists,
    may_open: Callable[[str], bool] = lambda path: os.access(path, os.R_OK | os.W_OK),
) -> list[str]:
    """Why a device output cannot be opened, one line per problem naming its key (``where`` is the
    servo section's, e.g. ``robot 'arm': servo``) and what to do."""
    problems = []
    for i, output in enumerate(options.outputs):
        if isinstance(output, I2cOutput):
            key, path = f"{where}.outputs[{i}].bus", output.device
            missing = (
                f"{path} does not exist: enable I²C (Raspberry Pi: raspi-config → Interface Options → "
                "I2C, or dtparam=i2c_arm=on in config.txt) and check the bus number with ls /dev/i2c-*"
            )
            group = "i2c"
        elif isinstance(output, SerialOutput):
            key, path = f"{where}.outputs[{i}].port", output.port
            missing = (
                f"serial port {path} does not exist: is the board plugged in? "
                "ls /dev/serial/by-id/ lists the serial ports there are"
            )
            group = "dialout"
        else:
            continue
        if not exists(path):
            problems.append(f"{key}: {missing}")
        elif not may_open(path):
            problems.append(
                f"{key}: no permission to open {path}: add your user to the {group} group "
                f"(sudo usermod -aG {group} $USER) and log in again"
            )
    return problems
