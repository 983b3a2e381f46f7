"""Pca9685Link against PCA9685 models on a fake smbus2 bus: what the boards' registers hold and the
pulses they make after start-up, writes, off and a failing bus (tests/boards/pca9685_model.py is
the datasheet's chip)."""

from __future__ import annotations

import errno
import math
import os
from collections.abc import Sequence

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.boards.pca9685_model import Channel, FakeSmbus, ModelClock
from urdaemon.backends.servo.i2c_link import Pca9685Link
from urdaemon.cell.servo import I2cOutput

FULL_OFF = Channel(0, 0, False, True)


def make(
    channels: Sequence[int],
    *,
    addresses: tuple[int, ...] = (0x40,),
    frequency_hz: float = 50.0,
    oscillator_hz: float = 25e6,
    bus_number: int = 1,
) -> tuple[Pca9685Link, FakeSmbus]:
    """A link on a fresh bus whose boards run at ``oscillator_hz``, the same in the cell file."""
    clock = ModelClock()
    bus = FakeSmbus.with_boards(addresses, clock, oscillator_hz)
    bus.close()  # as smbus2 before open: every access must come after the link opened the bus
    output = I2cOutput(kind="i2c", bus=bus_number, address=addresses, oscillator_hz=oscillator_hz)
    link = Pca9685Link(output, frequency_hz, channels, open_bus=bus.open, sleep=clock.advance)
    return link, bus


def expected_count(pulse_us: float, prescale: int, oscillator_hz: float) -> int:
    """The OFF count of a pulse: the pulse in oscillator cycles over (PRE_SCALE + 1), rounded, 1..4095."""
    return min(max(math.floor(pulse_us * oscillator_hz / ((prescale + 1) * 1e6) + 0.5), 0), 4095)


def assert_clean(bus: FakeSmbus) -> None:
    for address, board in bus.boards.items():
        assert board.violations == [], f"0x{address:02x}"


# --- start-up ---

STARTUPS = [
    # (frequency Hz, oscillator Hz, PRE_SCALE): round(osc / (4096 × f)) − 1
    (50.0, 25e6, 121),
    (200.0, 25e6, 30),
    (330.0, 25e6, 17),
    (24.0, 25e6, 253),
    (1526.0, 25e6, 3),
    (50.0, 26.6e6, 129),
    (60.0, 23.5e6, 95),
]


@pytest.mark.parametrize(("frequency_hz", "oscillator_hz", "prescale"), STARTUPS)
def test_open_starts_every_board_awake_with_auto_increment(
    frequency_hz: float, oscillator_hz: float, prescale: int
) -> None:
    link, bus = make([0, 16], addresses=(0x40, 0x41), frequency_hz=frequency_hz, oscillator_hz=oscillator_hz)
    link.open()
    for board in bus.boards.values():
        assert board.register(0x00) == 0x20  # AI; SLEEP, ALLCALL, SUBx and RESTART clear
        assert board.register(0x01) == 0x04
        assert board.prescale == prescale
        assert board.running
        assert not board.halted
        assert board.channels() == [FULL_OFF] * 16  # start-up writes no channel
        assert board.period_us == pytest.approx(1e6 / frequency_hz, rel=0.125)
    assert bus.opened == [1]
    assert bus.count("write_block") == 0
    assert bus.boards[0x40].clock.now_ns >= 500_000
    assert_clean(bus)


def test_open_on_the_configured_bus_number() -> None:
    link, bus = make([0], bus_number=3)
    link.open()
    assert bus.opened == [3]


def test_open_restarts_a_board_left_running_by_an_earlier_run() -> None:
    link, bus = make([0, 1])
    link.open()
    link.write([1500.0, 1000.0])
    link.close()
    bus.boards[0x40].clock.advance(1.0)
    link.open()  # sleeps with channels running (RESTART set), wakes, restarts
    board = bus.boards[0x40]
    assert board.running
    assert not board.halted
    assert board.pulse_us(0) == pytest.approx(1500.0, abs=board.period_us / 4096)
    assert_clean(bus)


def test_the_chain_answers_only_its_own_addresses_after_open() -> None:
    link, bus = make([0, 16], addresses=(0x40, 0x41))
    link.open()
    with pytest.raises(OSError, match="0x70") as raised:
        bus.open(1).write_byte_data(0x70, 0x01, 0x00)  # the LED All Call address
    assert raised.value.errno == errno.ENXIO


def test_a_board_strapped_at_the_all_call_address_starts_with_the_chain() -> None:
    link, bus = make([0, 16], addresses=(0x70, 0x40))  # 0x70: every fresh board's LED All Call address
    link.open()
    for board in bus.boards.values():
        assert (board.register(0x00), board.prescale) == (0x20, 121)
    link.write([1500.0, 1000.0])
    assert bus.boards[0x70].channels()[0].off == 307
    assert bus.boards[0x40].channels()[0].off == 205
    assert_clean(bus)


# --- writes ---


def test_counts_in_the_led_registers_follow_the_pulses() -> None:
    channels = [0, 5, 6, 15]
    pulses = [500.0, 1500.0, 1499.0, 2500.0]
    link, bus = make(channels)
    link.open()
    link.write(pulses)
    board = bus.boards[0x40]
    image = board.channels()
    for channel, pulse in zip(channels, pulses, strict=True):
        assert image[channel] == Channel(0, expected_count(pulse, 121, 25e6), False, False)
    assert [image[c] for c in range(16) if c not in channels] == [FULL_OFF] * 12
    assert [image[c].off for c in channels] == [102, 307, 307, 512]
    assert_clean(bus)


@settings(max_examples=60, deadline=None)
@given(
    oscillator_hz=st.floats(23e6, 27e6),
    share=st.floats(0.0, 1.0),
    shares=st.lists(st.floats(0.0, 1.0), min_size=3, max_size=3),
)
def test_the_pulse_the_board_makes_is_the_requested_one_within_half_a_count(
    oscillator_hz: float, share: float, shares: list[float]
) -> None:
    slowest = oscillator_hz / (4096 * 255.4)  # PRE_SCALE 255 (and the hardware's minimum of 3 is far)
    frequency_hz = slowest + share * (400.0 - slowest)
    prescale = math.floor(oscillator_hz / (4096 * frequency_hz) + 0.5) - 1
    period_us = (prescale + 1) * 4096 / oscillator_hz * 1e6
    pulses = [100.0 + share * (period_us - 200.0) for share in shares]
    link, bus = make([2, 9, 13], frequency_hz=frequency_hz, oscillator_hz=oscillator_hz)
    link.open()
    link.write(pulses)
    board = bus.boards[0x40]
    assert board.prescale == prescale
    for channel, pulse in zip([2, 9, 13], pulses, strict=True):
        assert abs(board.pulse_us(channel) - pulse) <= period_us / 4096 / 2 + 1e-6
    assert_clean(bus)


def test_an_identical_write_makes_no_transfer() -> None:
    link, bus = make([0, 1, 2])
    link.open()
    assert link.write([1000.0, 1500.0, 2000.0]) == 1
    transfers = len(bus.log)
    assert link.write([1000.0, 1500.0, 2000.0]) == 0
    assert link.write([1001.0, 1500.0, 2000.0]) == 0  # the same count (205.12 → 205)
    assert len(bus.log) == transfers


def test_one_changed_channel_is_one_block_write_of_its_4_registers() -> None:
    link, bus = make([0, 1, 2])
    link.open()
    link.write([1000.0, 1500.0, 2000.0])
    before = bus.count("write_block")
    assert link.write([1000.0, 1600.0, 2000.0]) == 1
    assert bus.count("write_block") == before + 1
    last = bus.log[-1]
    assert (last.kind, last.address, last.data) == ("write_block", 0x40, bytes([0x0A, 0, 0, 72, 1]))


def test_ten_changed_channels_in_a_row_are_two_block_writes() -> None:
    link, bus = make(list(range(3, 13)))
    link.open()
    assert link.write([1500.0] * 10) == 2
    blocks = [t for t in bus.log if t.kind == "write_block"]
    assert [(t.data[0], len(t.data) - 1) for t in blocks] == [(0x06 + 12, 32), (0x06 + 44, 8)]
    assert all(bus.boards[0x40].channels()[c].off == 307 for c in range(3, 13))
    assert_clean(bus)


def test_chained_boards_get_their_own_channels() -> None:
    link, bus = make([3, 17], addresses=(0x40, 0x41))
    link.open()
    assert link.write([1200.0, 1800.0]) == 2
    first, second = bus.boards[0x40].channels(), bus.boards[0x41].channels()
    assert first[3] == Channel(0, 246, False, False)  # 245.90
    assert second[1] == Channel(0, 369, False, False)  # 368.85
    assert [c for c in range(16) if first[c] != FULL_OFF] == [3]
    assert [c for c in range(16) if second[c] != FULL_OFF] == [1]
    assert {t.address for t in bus.log if t.kind == "write_block"} == {0x40, 0x41}
    assert_clean(bus)


def test_every_block_fits_an_smbus_block() -> None:
    link, bus = make(list(range(32)), addresses=(0x40, 0x41))
    link.open()
    for step in range(5):
        link.write([1000.0 + 37.0 * step * (c % 3) for c in range(32)])
    assert all(len(t.data) - 1 <= 32 for t in bus.log)
    assert_clean(bus)


def test_a_wrong_number_of_pulses_is_refused() -> None:
    link, _ = make([0, 1])
    link.open()
    with pytest.raises(ValueError, match="zip"):
        link.write([1500.0])


# --- off ---


def test_off_sets_full_off_everywhere_in_one_write_per_board() -> None:
    link, bus = make([0, 7, 16, 31], addresses=(0x40, 0x41))
    link.open()
    link.write([1000.0, 1200.0, 1400.0, 1600.0])
    transfers = len(bus.log)
    link.off()
    assert len(bus.log) == transfers + 2
    assert {(t.kind, t.address, t.data) for t in bus.log[transfers:]} == {
        ("write_byte", 0x40, bytes([0xFD, 0x10])),
        ("write_byte", 0x41, bytes([0xFD, 0x10])),
    }
    for board in bus.boards.values():
        assert [board.pulse_us(c) for c in range(16)] == [0.0] * 16
        assert all(c.full_off for c in board.channels())
    assert link.write([1000.0, 1200.0, 1400.0, 1600.0]) == 4  # every channel back
    assert bus.boards[0x41].pulse_us(15) == pytest.approx(1600.0, abs=3.0)
    assert_clean(bus)


def test_off_before_open_touches_nothing() -> None:
    link, bus = make([0])
    link.off()
    assert bus.log == []


# --- a failing bus ---


@pytest.mark.parametrize("code", [errno.EIO, errno.ENODEV, errno.EREMOTEIO])
def test_a_failing_bus_raises_oserror_from_open_and_write(code: int) -> None:
    link, bus = make([0, 1])
    link.open()
    bus.fail(code)
    with pytest.raises(OSError, match=os.strerror(code)) as raised:
        link.write([1000.0, 2000.0])
    assert raised.value.errno == code
    with pytest.raises(OSError, match=os.strerror(code)) as raised:
        link.open()
    assert raised.value.errno == code
    link.close()  # never raises, even on a failing bus
    bus.heal()
    link.open()
    assert link.write([1000.0, 2000.0]) == 1
    assert bus.boards[0x40].pulse_us(1) == pytest.approx(2000.0, abs=3.0)


def test_write_before_open_raises_oserror() -> None:
    link, _ = make([0])
    with pytest.raises(OSError, match="not open"):
        link.write([1500.0])


def test_a_block_that_failed_is_written_again_and_only_it() -> None:
    link, bus = make(list(range(10)))
    link.open()
    bus.fail(errno.EREMOTEIO, times=1, after=1)  # the first block goes through, the second fails
    with pytest.raises(OSError, match="Remote I/O"):
        link.write([1500.0] * 10)
    assert link.write([1500.0] * 10) == 1
    last = bus.log[-1]
    assert (last.data[0], len(last.data) - 1) == (0x06 + 32, 8)
    assert all(bus.boards[0x40].channels()[c].off == 307 for c in range(10))


# --- close and open again ---


def test_after_close_and_open_every_channel_is_written_again() -> None:
    link, bus = make([0, 1, 2, 20], addresses=(0x40, 0x41))
    link.open()
    link.write([1000.0, 1500.0, 2000.0, 1200.0])
    link.close()
    assert bus.closes == 2
    assert not bus.is_open
    link.open()
    before = bus.count("write_block")
    assert link.write([1000.0, 1500.0, 2000.0, 1200.0]) == 2
    assert bus.count("write_block") == before + 2
    assert bus.opened == [1, 1]
    assert_clean(bus)


# --- check: is the board still there, as it was left? ---


def test_check_passes_boards_that_run_as_started() -> None:
    link, bus = make([0, 17], addresses=(0x40, 0x41))
    link.open()
    link.write([1500.0, 1500.0])
    link.check()
    assert bus.count("read_byte") == 2  # MODE1 of each board, nothing written
    assert_clean(bus)


def test_check_finds_a_board_that_lost_power_and_open_restores_it() -> None:
    link, bus = make([0, 17], addresses=(0x40, 0x41))
    link.open()
    link.write([1500.0, 1200.0])
    bus.boards[0x41].power_on()  # a brown-out: MODE1 asleep, every channel full off
    with pytest.raises(OSError, match=r"board 0x41 was reset \(MODE1 0x11\); starting it again"):
        link.check()
    link.close()
    link.open()
    link.write([1500.0, 1200.0])  # the writer writes its last frame again after opening
    assert bus.boards[0x41].pulse_us(1) == pytest.approx(1200.0, abs=5.0)
    assert bus.boards[0x40].pulse_us(0) == pytest.approx(1500.0, abs=5.0)
    assert_clean(bus)


def test_check_fails_when_the_board_does_not_answer() -> None:
    link, bus = make([0])
    link.open()
    bus.fail(errno.EREMOTEIO)
    with pytest.raises(OSError, match="Remote I/O error") as failed:
        link.check()
    assert failed.value.errno == errno.EREMOTEIO
