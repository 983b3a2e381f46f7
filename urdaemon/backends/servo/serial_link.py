"""A serial servo controller that takes SSC-32 command lines (an SSC-32 board, the Arduino bridge in
examples/arduino/), through a pyserial-shaped port: each frame's changed channels in one command
group (boards/ssc32.py computes the line)."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Sequence
from typing import Protocol

from urdaemon.boards import ssc32
from urdaemon.cell.servo import SerialOutput

__all__ = ["SerialLike", "Ssc32Link", "open_serial"]

WRITE_TIMEOUT_S = 1.0
"""A line the port has not taken in this time counts as a failed write (a board that stopped
reading): the link is closed and opened again."""
READ_TIMEOUT_S = 0.05
"""How long one read waits for the board's answer while opening."""
READY_WAIT_S = 3.0
"""How long opening waits for the board to answer ``VER``: an Arduino restarts when its port opens
and its boot loader takes a second or two, and a line sent meanwhile is lost. A controller that
never answers is driven anyway once this has passed."""
VER_EVERY_S = 0.5
"""How often ``VER`` is sent again while waiting (the first may reach the boot loader)."""


class SerialLike(Protocol):
    """The part of ``serial.Serial`` the link uses."""

    def write(self, data: bytes) -> int | None:
        """Queue ``data`` for sending."""
        ...

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` received bytes, waiting at most the port's read timeout."""
        ...

    def close(self) -> None:
        """Close the port."""
        ...


def open_serial(output: SerialOutput) -> SerialLike:
    """The output's port through pyserial: 8N1 at its baud rate, no flow control."""
    import serial

    port: SerialLike = serial.Serial(
        output.port, output.baud, timeout=READ_TIMEOUT_S, write_timeout=WRITE_TIMEOUT_S
    )
    return port


class Ssc32Link:
    """One serial output."""

    def __init__(
        self,
        output: SerialOutput,
        channels: Sequence[int],
        *,
        open_port: Callable[[SerialOutput], SerialLike] = open_serial,
        ready_wait_s: float = READY_WAIT_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.label = output.label
        self._output = output
        self._channels = tuple(channels)
        self._open_port = open_port
        self._ready_wait = ready_wait_s
        self._clock = clock
        self.answered = ""
        """The board's answer to ``VER`` at the last open (empty: it did not answer)."""
        self._port: SerialLike | None = None
        self._sent: dict[int, int] = {}
        """The pulse each channel was last sent (µs; 0: off); a channel not here was not sent yet."""

    def open(self) -> None:
        """Open the port and wait (bounded) until the board answers ``VER``, so the first frame is not
        lost to a board that is still starting."""
        self.close()
        port = self._port = self._open_port(self._output)
        self.answered = self._await_answer(port)

    def _await_answer(self, port: SerialLike) -> str:
        start = self._clock()
        asked = start - VER_EVERY_S
        received = b""
        while self._clock() - start < self._ready_wait:
            if self._clock() - asked >= VER_EVERY_S:
                port.write(ssc32.VERSION_QUERY)
                asked = self._clock()
            received = (received + port.read(64))[-256:]
            *complete, _partial = received.replace(b"\n", b"\r").split(b"\r")
            answers = [line.strip() for line in complete if line.strip()]
            if answers:
                return answers[-1].decode("ascii", "replace")
        return ""

    def write(self, pulses: Sequence[float]) -> int:
        """Send the changed channels' pulses, whole microseconds, as one command group; 1 line or 0."""
        port = self._port
        if port is None:
            raise OSError(f"{self.label} is not open")
        sent = self._sent
        moves = []
        for channel, pulse in zip(self._channels, pulses, strict=True):
            us = int(pulse + 0.5)
            if sent.get(channel) != us:
                moves.append((channel, us))
        if not moves:
            return 0
        port.write(ssc32.group_line(moves, self._output.move_time_ms))
        sent.update(moves)
        return 1

    def check(self) -> None:
        """Read what the board sent: an unplugged port fails the read (``OSError``), and a line from a
        board that was not asked anything means it restarted (an Arduino after a brown-out) and holds
        no pulses: ``OSError`` too, so the writer opens it again and sends every channel."""
        port = self._port
        if port is None:
            raise OSError(f"{self.label} is not open")
        said = port.read(256)
        if said.strip(b"\r\n\t "):
            text = said.strip().decode("ascii", "replace")
            raise OSError(f"{self.label} restarted (it said {text!r}); sending every channel again")

    def off(self) -> None:
        """Stop every configured channel's pulses (``P0``)."""
        port = self._port
        if port is not None:
            port.write(ssc32.off_line(self._channels))
            self._sent = dict.fromkeys(self._channels, 0)

    def close(self) -> None:
        """Close the port; what was sent is forgotten (a board may be reset before the next open)."""
        port, self._port = self._port, None
        self._sent = {}
        if port is not None:
            with contextlib.suppress(OSError):  # unplugged: nothing left to release
                port.close()
