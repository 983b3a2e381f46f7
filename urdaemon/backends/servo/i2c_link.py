"""PCA9685 boards on a Linux I²C bus, through an smbus2-shaped bus: start-up as the datasheet gives
it, then each frame's changed channels in one block write per run (boards/pca9685.py computes the
bytes)."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Sequence
from typing import Protocol

from urdaemon.boards import pca9685
from urdaemon.cell.servo import I2cOutput

__all__ = ["Pca9685Link", "SMBusLike", "open_smbus"]


class SMBusLike(Protocol):
    """The part of ``smbus2.SMBus`` the link uses."""

    def write_byte_data(self, i2c_addr: int, register: int, value: int) -> None:
        """Write one register."""
        ...

    def read_byte_data(self, i2c_addr: int, register: int) -> int:
        """Read one register."""
        ...

    def write_i2c_block_data(self, i2c_addr: int, register: int, data: Sequence[int]) -> None:
        """Write ``data`` from ``register`` on (at most 32 bytes)."""
        ...

    def close(self) -> None:
        """Close the bus's device file."""
        ...


def open_smbus(bus: int) -> SMBusLike:
    """``/dev/i2c-<bus>`` through smbus2."""
    from smbus2 import SMBus

    return SMBus(bus)


class Pca9685Link:
    """One I²C output: a chain of PCA9685 boards, channel ``c`` on board ``c // 16``."""

    def __init__(
        self,
        output: I2cOutput,
        frequency_hz: float,
        channels: Sequence[int],
        *,
        open_bus: Callable[[int], SMBusLike] = open_smbus,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.label = output.label
        self._output = output
        self._addresses = output.address
        self.prescale = pca9685.prescale_for(frequency_hz, output.oscillator_hz)
        self._channels = [divmod(c, pca9685.CHANNELS) for c in channels]
        self._open_bus = open_bus
        self._sleep = sleep
        self._bus: SMBusLike | None = None
        self._boards: list[list[int | None]] = [[None] * pca9685.CHANNELS for _ in self._addresses]
        """What each board's channel registers hold, as far as we know (None: not known)."""

    def open(self) -> None:
        """Open the bus and start every board (datasheet §7.3.1: sleep, prescale, wake, restart)."""
        self.close()
        bus = self._bus = self._open_bus(self._output.bus)
        until_wake, after_settle = pca9685.startup_writes(self.prescale)
        for address in self._addresses:
            for register, value in until_wake:
                bus.write_byte_data(address, register, value)
        self._sleep(pca9685.OSCILLATOR_SETTLE_S)
        for address in self._addresses:
            for register, value in after_settle:
                bus.write_byte_data(address, register, value)
        for board in self._boards:
            board[:] = [None] * pca9685.CHANNELS

    def write(self, pulses: Sequence[float]) -> int:
        """Write the changed channels' counts; the block writes it took."""
        bus = self._bus
        if bus is None:
            raise OSError(f"{self.label} is not open")
        frames: list[list[int | None]] = [[None] * pca9685.CHANNELS for _ in self._addresses]
        for (index, pin), pulse in zip(self._channels, pulses, strict=True):
            frames[index][pin] = pca9685.count_for(pulse, self.prescale, self._output.oscillator_hz)
        transfers = 0
        for address, board, frame in zip(self._addresses, self._boards, frames, strict=True):
            for register, data in pca9685.block_writes(board, frame):
                bus.write_i2c_block_data(address, register, list(data))
                first = (register - pca9685.LED0_ON_L) // 4
                for pin in range(first, first + len(data) // 4):
                    board[pin] = frame[pin]
                transfers += 1
        return transfers

    def check(self) -> None:
        """Read every board's MODE1: it must answer, awake and auto-incrementing as started; a board
        that lost power comes back asleep (``OSError``: the writer starts it again)."""
        bus = self._bus
        if bus is None:
            raise OSError(f"{self.label} is not open")
        for address in self._output.address:
            mode1 = bus.read_byte_data(address, pca9685.MODE1)
            if mode1 & (pca9685.MODE1_SLEEP | pca9685.MODE1_AI) != pca9685.MODE1_AI:
                raise OSError(f"board {address:#04x} was reset (MODE1 {mode1:#04x}); starting it again")

    def off(self) -> None:
        """Set "full off" on every channel of every board (one ALL_LED write per board)."""
        bus = self._bus
        if bus is None:
            return
        register, value = pca9685.ALL_OFF_WRITE
        for address, board in zip(self._addresses, self._boards, strict=True):
            bus.write_byte_data(address, register, value)
            board[:] = [pca9685.FULL_OFF] * pca9685.CHANNELS

    def close(self) -> None:
        """Close the bus; the boards' images are forgotten (a board may be reset before the next open)."""
        bus, self._bus = self._bus, None
        for board in self._boards:
            board[:] = [None] * pca9685.CHANNELS
        if bus is not None:
            with contextlib.suppress(OSError):  # the adapter is gone already: nothing to release
                bus.close()
