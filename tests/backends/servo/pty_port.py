"""A pseudo-terminal standing in for a serial servo controller: the code under test opens the slave's
path as its serial port, the test reads what arrives on the master end as SSC-32 command lines.

Every read is bounded: ``select`` with a timeout, and loops with a fixed number of turns.
"""

from __future__ import annotations

import contextlib
import os
import re
import select
import termios
import tty
from collections.abc import Mapping
from typing import Any

__all__ = ["PtyPort", "apply_line", "parse_line"]

_READ_SIZE = 4096
_MAX_READS = 1000
"""Reads of one ``lines`` call at most: far more than any test sends."""

_LINE = re.compile(rb"^((?:#\d+P\d+)+)(?:T(\d+))?$")
_MOVE = re.compile(rb"#(\d+)P(\d+)")


def parse_line(line: bytes) -> tuple[dict[int, int], int | None]:
    """A command group (without its carriage return) as {channel: pulse µs} and its ``T`` (None:
    none); AssertionError when the line is not an SSC-32 command group."""
    match = _LINE.match(line)
    assert match is not None, f"not an SSC-32 command group: {line!r}"
    moves = [(int(c), int(p)) for c, p in _MOVE.findall(match.group(1))]
    channels = [c for c, _ in moves]
    assert len(set(channels)) == len(channels), f"a channel twice in one group: {line!r}"
    time_ms = match.group(2)
    return dict(moves), None if time_ms is None else int(time_ms)


def apply_line(board: Mapping[int, int], line: bytes) -> dict[int, int]:
    """What a board's channels hold after ``line`` (the channels it does not name keep their pulse)."""
    moves, _ = parse_line(line)
    return {**board, **moves}


VERSION = b"SSC32-V2.50USB"
"""What the stand-in board answers to ``VER``, as an SSC-32 does."""


class PtyPort:
    """One pseudo-terminal; ``path`` is the port to open. The test keeps a slave descriptor of its
    own open, so the master can be read while the code under test has the port closed.

    It answers ``VER`` as an SSC-32 does while its lines are read (``lines``, ``feed``); the queries
    are counted in ``queries`` and are not among the lines returned."""

    def __init__(self, *, answers: bool = True) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no line editing, no newline translation: bytes as they are
        self.master: int | None = master
        self._slave: int | None = slave
        self.path = os.ttyname(slave)
        self._buffer = b""
        self._ready: list[bytes] = []
        self._answers = answers
        self.queries = 0
        """``VER`` lines received."""

    def lines(self, count: int, timeout: float = 5.0) -> list[bytes]:
        """The next ``count`` command lines (each without its ``\\r``), waiting at most ``timeout`` s
        for each read; AssertionError if they do not come."""
        assert self.master is not None, "the port was unplugged"
        for _ in range(_MAX_READS):
            *parts, self._buffer = self._buffer.split(b"\r")
            self._ready += self._commands(parts)
            if len(self._ready) >= count:
                break
            ready, _, _ = select.select([self.master], [], [], timeout)
            assert ready, f"no line within {timeout} s; received so far: {self._ready!r} {self._buffer!r}"
            self._buffer += os.read(self.master, _READ_SIZE)
        assert len(self._ready) >= count, f"{count} lines wanted, got {self._ready!r}"
        found, self._ready = self._ready[:count], self._ready[count:]
        return found

    def answer(self, timeout: float = 5.0) -> None:
        """Read until a ``VER`` query came (and was answered); the command lines read meanwhile stay
        for ``lines``."""
        assert self.master is not None, "the port was unplugged"
        seen = self.queries
        for _ in range(_MAX_READS):
            *parts, self._buffer = self._buffer.split(b"\r")
            self._ready += self._commands(parts)
            if self.queries > seen:
                return
            ready, _, _ = select.select([self.master], [], [], timeout)
            assert ready, f"no VER within {timeout} s; received so far: {self._buffer!r}"
            self._buffer += os.read(self.master, _READ_SIZE)
        raise AssertionError("no VER")

    def line(self, timeout: float = 5.0) -> bytes:
        """The next line (without its ``\\r``)."""
        return self.lines(1, timeout)[0]

    def feed(self, data: bytes) -> list[bytes]:
        """Take ``data`` read from the master elsewhere (an event loop's reader); the lines it completes."""
        *parts, self._buffer = (self._buffer + data).split(b"\r")
        return self._commands(parts)

    def _commands(self, lines: list[bytes]) -> list[bytes]:
        """``lines`` without the ``VER`` queries, each answered (when this board answers)."""
        commands = []
        for line in lines:
            if line == b"VER":
                self.queries += 1
                if self._answers and self.master is not None:
                    os.write(self.master, VERSION + b"\r")
            else:
                commands.append(line)
        return commands

    @property
    def partial(self) -> bytes:
        """What arrived after the last complete line."""
        return self._buffer

    def attributes(self) -> list[Any]:
        """The terminal's settings (``termios.tcgetattr``) as the code under test left them."""
        assert self._slave is not None, "the port was unplugged"
        return termios.tcgetattr(self._slave)

    def set_attributes(self, attributes: list[Any]) -> None:
        """Change the terminal's settings (``termios.tcsetattr``) before the code under test opens it."""
        assert self._slave is not None, "the port was unplugged"
        termios.tcsetattr(self._slave, termios.TCSANOW, attributes)

    def unplug(self) -> None:
        """Close the master end, as pulling the controller's USB cable ends its port: the slave device
        goes away, and writes on descriptors still open fail."""
        master, self.master = self.master, None
        if master is not None:
            os.close(master)
        self._close_slave()

    def close(self) -> None:
        """Release both ends."""
        self.unplug()

    def _close_slave(self) -> None:
        slave, self._slave = self._slave, None
        if slave is not None:
            with contextlib.suppress(OSError):
                os.close(slave)
