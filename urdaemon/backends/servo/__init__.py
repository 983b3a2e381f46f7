"""The ``servo`` backend: a hobby-servo arm driven through PCA9685 boards on I²C, a serial SSC-32
controller, or the Zenoh key (docs/servo.md)."""

from __future__ import annotations

from urdaemon.backends.servo.backend import ServoBackend
from urdaemon.backends.servo.mapping import ServoMapping

__all__ = ["ServoBackend", "ServoMapping"]
