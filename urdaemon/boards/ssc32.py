"""The SSC-32 serial servo controller's command lines (Lynxmotion SSC-32/SSC-32U manual), which many
16/32-channel boards and the Arduino bridge in examples/arduino/ also take. Pure: lines are computed
here and written by backends/servo/serial_link.py.

A command group ``#<ch>P<pulse µs>`` … ``T<ms>`` ending in a carriage return moves every channel it
names at once; ``T`` spreads the move over that time. ``P0`` stops a channel's pulses.
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["CHANNELS", "MOVE_TIME_RANGE_MS", "PULSE_RANGE_US", "VERSION_QUERY", "group_line", "off_line"]

CHANNELS = 32
"""Channels of an SSC-32 (0..31)."""
PULSE_RANGE_US = (500, 2500)
"""Pulses the board makes; it clamps a number outside to the nearest end (0 means off)."""
MOVE_TIME_RANGE_MS = (1, 65535)
"""What ``T`` takes."""
VERSION_QUERY = b"VER\r"
"""Asks the board for its version line (answered with a line ending in a carriage return)."""


def group_line(pulses: Sequence[tuple[int, int]], move_time_ms: int | None = None) -> bytes:
    """One command group moving each (channel, pulse µs) at once, optionally over ``move_time_ms``;
    empty when there is nothing to move."""
    if not pulses:
        return b""
    body = "".join(f"#{channel}P{pulse}" for channel, pulse in pulses)
    if move_time_ms is not None:
        body += f"T{move_time_ms}"
    return f"{body}\r".encode("ascii")


def off_line(channels: Sequence[int]) -> bytes:
    """One command group that stops the pulses of ``channels`` (the servos go limp)."""
    return group_line([(channel, 0) for channel in channels])
