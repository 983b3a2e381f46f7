"""What a servo output's writer thread drives: a board link, blocking, one per output device."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

__all__ = ["BoardLink"]


class BoardLink(Protocol):
    """One output device (PCA9685 boards on a bus, a serial controller). Every method blocks and
    raises ``OSError`` when the device fails; only the output's writer thread calls them."""

    label: str
    """How reports and messages name the output (``i2c bus 1 (0x40)``, ``serial /dev/ttyUSB0``)."""

    def open(self) -> None:
        """Open the device and bring the board up; after this, the next ``write`` writes every channel."""
        ...

    def write(self, pulses: Sequence[float]) -> int:
        """Put the pulses (µs, one per configured joint) on the board; the bus transfers it took
        (channels that did not change are not written again)."""
        ...

    def check(self) -> None:
        """Ask the device whether it is still there and as it was left (the writer asks while there
        is nothing to write); ``OSError`` when it is gone or was reset (it is opened again)."""
        ...

    def off(self) -> None:
        """Stop every pulse (the servos go limp)."""
        ...

    def close(self) -> None:
        """Release the device; never raises."""
        ...
