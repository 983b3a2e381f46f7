"""The PCA9685 16-channel, 12-bit PWM controller, from its datasheet (NXP PCA9685, rev. 4): register
addresses and bits, the prescale and count formulas, the start-up sequence, and which block writes
bring a board from one image of its channel registers to the next. Pure: bytes are computed here and
written by backends/servo/i2c_link.py.

Every channel n has four registers from ``LED0_ON_L + 4 n``: ON_L, ON_H, OFF_L, OFF_H. The output
goes high at count ON and low at count OFF of each 4096-count period; bit 4 of ON_H is "full on",
bit 4 of OFF_H "full off" (full off wins). A servo pulse is ON = 0, OFF = the pulse in counts.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = [
    "ALL_LED_OFF_H",
    "ALL_LED_ON_L",
    "ALL_OFF_WRITE",
    "CHANNELS",
    "DEFAULT_OSCILLATOR_HZ",
    "FREQUENCY_RANGE_HZ",
    "FULL_OFF",
    "FULL_ON_OFF_BIT",
    "LED0_ON_L",
    "MAX_BLOCK_CHANNELS",
    "MODE1",
    "MODE1_AI",
    "MODE1_ALLCALL",
    "MODE1_RESTART",
    "MODE1_SLEEP",
    "MODE2",
    "MODE2_OUTDRV",
    "OSCILLATOR_SETTLE_S",
    "PRESCALE",
    "PRESCALE_RANGE",
    "RESOLUTION",
    "block_writes",
    "channel_bytes",
    "count_for",
    "frequency_of",
    "prescale_for",
    "startup_writes",
]

CHANNELS = 16
"""PWM outputs per board (LED0..LED15)."""
RESOLUTION = 4096
"""Counts per PWM period (12 bits)."""
DEFAULT_OSCILLATOR_HZ = 25_000_000.0
"""The internal oscillator's nominal frequency; real boards differ by a few per cent."""
FREQUENCY_RANGE_HZ = (24.0, 1526.0)
"""Output frequencies the prescale reaches with the 25 MHz oscillator (prescale 255 .. 3)."""
PRESCALE_RANGE = (3, 255)
"""PRE_SCALE values the chip takes; it raises a value below 3 to 3."""
OSCILLATOR_SETTLE_S = 500e-6
"""After SLEEP is cleared, the oscillator needs this long before RESTART may be written."""

MODE1 = 0x00
MODE2 = 0x01
LED0_ON_L = 0x06
ALL_LED_ON_L = 0xFA
ALL_LED_OFF_H = 0xFD
PRESCALE = 0xFE

MODE1_RESTART = 0x80
MODE1_AI = 0x20
"""Auto-increment: the register pointer moves on after each byte, so one block write fills a run."""
MODE1_SLEEP = 0x10
MODE1_ALLCALL = 0x01
MODE2_OUTDRV = 0x04
"""Totem-pole outputs (the power-on default; servo boards drive the signal line directly)."""
FULL_ON_OFF_BIT = 0x10
"""Bit 4 of ON_H (full on) and of OFF_H (full off)."""

FULL_OFF = -1
"""The count that stands for "full off" in a channel image (no pulse at all)."""
MAX_BLOCK_CHANNELS = 8
"""Channels per block write: an SMBus block carries at most 32 data bytes, 4 per channel."""


def prescale_for(frequency_hz: float, oscillator_hz: float = DEFAULT_OSCILLATOR_HZ) -> int:
    """PRE_SCALE for an output frequency: round(osc / (4096 × f)) − 1 (datasheet eq. 1).

    ValueError when the result is outside 3..255 (the chip cannot make that frequency)."""
    if not (math.isfinite(frequency_hz) and frequency_hz > 0 and oscillator_hz > 0):
        raise ValueError(f"no PCA9685 prescale for {frequency_hz!r} Hz at {oscillator_hz!r} Hz")
    value = math.floor(oscillator_hz / (RESOLUTION * frequency_hz) + 0.5) - 1
    low, high = PRESCALE_RANGE
    if not low <= value <= high:
        reach = (oscillator_hz / (RESOLUTION * (high + 1)), oscillator_hz / (RESOLUTION * (low + 1)))
        raise ValueError(
            f"a PCA9685 at {oscillator_hz / 1e6:g} MHz makes {reach[0]:.1f}–{reach[1]:.1f} Hz, "
            f"not {frequency_hz:g} Hz"
        )
    return value


def frequency_of(prescale: int, oscillator_hz: float = DEFAULT_OSCILLATOR_HZ) -> float:
    """The output frequency a PRE_SCALE value gives: osc / (4096 × (prescale + 1))."""
    return oscillator_hz / (RESOLUTION * (prescale + 1))


def count_for(pulse_us: float, prescale: int, oscillator_hz: float = DEFAULT_OSCILLATOR_HZ) -> int:
    """The OFF count of a pulse of ``pulse_us`` at that prescale: the pulse's share of the real period
    times 4096, rounded to the nearest count (datasheet §7.3.3's examples), within 0..4095."""
    # pulse × osc / ((prescale + 1) × 10⁶) in one division: exact for whole µs and Hz, so a count
    # that is exactly x.5 rounds up as the arithmetic says (the chain through the frequency did not)
    count = math.floor(pulse_us * oscillator_hz / ((prescale + 1) * 1_000_000) + 0.5)
    return 0 if count < 0 else RESOLUTION - 1 if count >= RESOLUTION else count


def channel_bytes(count: int) -> bytes:
    """ON_L, ON_H, OFF_L, OFF_H of one channel: ON at 0 and OFF at ``count``, or full off (also for
    count 0: datasheet §7.3.4 forbids programming ON and OFF with the same count)."""
    if count == FULL_OFF or count == 0:
        return bytes((0, 0, 0, FULL_ON_OFF_BIT))
    return bytes((0, 0, count & 0xFF, count >> 8))


def startup_writes(prescale: int) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """The start-up as (register, value) writes: those up to waking the oscillator, and those after it
    settled (``OSCILLATOR_SETTLE_S``). PRE_SCALE is written while asleep (the chip ignores it
    otherwise); MODE1 ends awake with auto-increment, all-call off (chained boards answer their own
    address only) and RESTART written, so channels that ran before the sleep run again."""
    if not PRESCALE_RANGE[0] <= prescale <= PRESCALE_RANGE[1]:
        raise ValueError(f"PRE_SCALE {prescale} is outside {PRESCALE_RANGE[0]}..{PRESCALE_RANGE[1]}")
    until_wake = [(MODE1, MODE1_SLEEP), (PRESCALE, prescale), (MODE2, MODE2_OUTDRV), (MODE1, MODE1_AI)]
    return until_wake, [(MODE1, MODE1_RESTART | MODE1_AI)]


ALL_OFF_WRITE = (ALL_LED_OFF_H, FULL_ON_OFF_BIT)
"""The one write that sets "full off" on all 16 channels at once (the ALL_LED registers)."""


def block_writes(board: Sequence[int | None], frame: Sequence[int | None]) -> list[tuple[int, bytes]]:
    """The writes that bring a board whose channels hold ``board`` to ``frame``: one block write
    (start register, bytes) per run of changed channels, at most ``MAX_BLOCK_CHANNELS`` long.

    Both are 16 counts (``FULL_OFF`` for no pulse); None in ``board`` is a channel whose contents are
    unknown (after start-up: always written), None in ``frame`` one nobody drives (never written).
    """
    writes: list[tuple[int, bytes]] = []
    start = -1
    data = bytearray()
    for channel in range(CHANNELS):
        wanted = frame[channel]
        if wanted is not None and wanted != board[channel]:
            if start >= 0 and channel - start < MAX_BLOCK_CHANNELS:
                data += channel_bytes(wanted)
                continue
            if start >= 0:
                writes.append((LED0_ON_L + 4 * start, bytes(data)))
            start, data = channel, bytearray(channel_bytes(wanted))
        elif start >= 0:
            writes.append((LED0_ON_L + 4 * start, bytes(data)))
            start = -1
    if start >= 0:
        writes.append((LED0_ON_L + 4 * start, bytes(data)))
    return writes
