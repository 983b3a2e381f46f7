"""The PCA9685 model against the datasheet's rules, table by table: it judges our driver and
Adafruit's, so it is tested first (a model that agrees with everything proves nothing)."""

from __future__ import annotations

import errno
import os

import pytest

from tests.boards.pca9685_model import (
    BusioI2C,
    Channel,
    DatasheetError,
    FakeSmbus,
    ModelClock,
    Pca9685Model,
    Transfer,
)

AI, SLEEP, RESTART, ALLCALL = 0x20, 0x10, 0x80, 0x01


def awake(clock: ModelClock | None = None, *, mode1: int = AI) -> Pca9685Model:
    """A board woken with ``mode1`` and left to settle."""
    board = Pca9685Model(clock)
    board.write([0x00, mode1])
    board.clock.advance(1e-3)
    return board


def running(channel: int = 0, on: int = 0, off: int = 300) -> Pca9685Model:
    """An awake board with one channel pulsing."""
    board = awake()
    board.write([0x06 + 4 * channel, on & 0xFF, on >> 8, off & 0xFF, off >> 8])
    return board


# --- power-on defaults (datasheet §7.3) ---

DEFAULTS = [
    (0x00, 0x11),  # MODE1: SLEEP | ALLCALL
    (0x01, 0x04),  # MODE2: OUTDRV
    (0x02, 0xE2),
    (0x03, 0xE4),
    (0x04, 0xE8),
    (0x05, 0xE0),
    (0xFE, 0x1E),  # PRE_SCALE: 200 Hz
    *((0x06 + 4 * n, 0x00) for n in range(16)),
    *((0x07 + 4 * n, 0x00) for n in range(16)),
    *((0x08 + 4 * n, 0x00) for n in range(16)),
    *((0x09 + 4 * n, 0x10) for n in range(16)),  # full off
]


@pytest.mark.parametrize(("register", "value"), DEFAULTS)
def test_power_on_value(register: int, value: int) -> None:
    assert Pca9685Model().register(register) == value


def test_power_on_board_is_asleep_with_every_channel_full_off() -> None:
    board = Pca9685Model()
    assert not board.running
    assert not board.halted
    assert board.channels() == [Channel(0, 0, False, True)] * 16
    assert [board.pulse_us(n) for n in range(16)] == [0.0] * 16


def test_reading_from_mode1_without_auto_increment_repeats_mode1() -> None:
    board = Pca9685Model()
    board.write([0x00])
    assert board.read(3) == bytes([0x11, 0x11, 0x11])


# --- the pointer and auto-increment ---

POINTER_CASES = [
    # (MODE1 while writing, written bytes, registers to check with expected values)
    (0x00, [0x06, 1, 2, 3, 4], {0x06: 4, 0x07: 0, 0x08: 0, 0x09: 0x10}),
    (AI, [0x06, 1, 2, 3, 4], {0x06: 1, 0x07: 2, 0x08: 3, 0x09: 4}),
    (AI, [0x0A, 0x22, 0x01, 0x33, 0x02], {0x0A: 0x22, 0x0B: 0x01, 0x0C: 0x33, 0x0D: 0x02}),
    # past LED15_OFF_H the pointer rolls over to MODE1: the third byte lands in MODE1
    (AI, [0x44, 0x55, 0x06, AI | ALLCALL, 0x04], {0x44: 0x55, 0x45: 0x06, 0x00: AI | ALLCALL, 0x01: 0x04}),
    # ON_H / OFF_H bits 7..5 are not writable
    (AI, [0x06, 0xFF, 0xFF, 0xFF, 0xFF], {0x06: 0xFF, 0x07: 0x1F, 0x08: 0xFF, 0x09: 0x1F}),
    # MODE2 bits 7..5 and the sub addresses' bit 0 are read only
    (AI, [0x01, 0xFF, 0xE3], {0x01: 0x1F, 0x02: 0xE2}),
]


@pytest.mark.parametrize(("mode1", "written", "expected"), POINTER_CASES)
def test_pointer_and_auto_increment(mode1: int, written: list[int], expected: dict[int, int]) -> None:
    board = awake(mode1=mode1)
    board.write(written)
    assert {r: board.register(r) for r in expected} == expected
    assert board.violations == []


def test_auto_increment_runs_from_all_led_to_prescale_then_mode1() -> None:
    board = Pca9685Model()  # asleep: PRE_SCALE takes writes
    board.write([0x00, SLEEP | AI])
    board.write([0xFA, 0, 0, 0, 0x10, 0x79, SLEEP | AI])
    assert board.prescale == 0x79
    assert board.register(0x00) == SLEEP | AI
    board.write([0xFC])
    assert board.read(4) == bytes([0, 0, 0x79, SLEEP | AI])  # ALL_LED reads zero


@pytest.mark.parametrize("mode1", [0x00, AI])
def test_reading_follows_auto_increment(mode1: int) -> None:
    board = awake(mode1=mode1)
    board.write([0x06, 0x00])
    board.write([0x09])
    expected = bytes([0x10, 0x00, 0x00, 0x00]) if mode1 else bytes([0x10] * 4)
    assert board.read(4) == expected


@pytest.mark.parametrize("register", [0x46, 0x47, 0x80, 0xF9, 0xFF])
def test_reserved_registers_and_test_mode_are_refused(register: int) -> None:
    board = awake()
    with pytest.raises(DatasheetError, match="reserved"):
        board.write([register, 0])
    with pytest.raises(DatasheetError, match="reserved"):
        board.write([register])


def test_auto_increment_never_reaches_a_reserved_register() -> None:
    board = awake()
    board.write([0x00])
    registers = board.read(70 + 3)  # MODE1..LED15_OFF_H, then MODE1 again
    assert registers[70:] == registers[:3] == bytes([AI, 0x04, 0xE2])


# --- PRE_SCALE (datasheet §7.3.5) ---

PRESCALE_CASES = [
    # (MODE1 when written, written value, stored value)
    (SLEEP, 121, 121),
    (SLEEP | AI, 255, 255),
    (SLEEP, 3, 3),
    (SLEEP, 2, 3),
    (SLEEP, 1, 3),
    (SLEEP, 0, 3),
    (AI, 121, 0x1E),  # awake: blocked
    (0x00, 3, 0x1E),
]


@pytest.mark.parametrize(("mode1", "value", "stored"), PRESCALE_CASES)
def test_prescale_takes_writes_only_asleep_and_at_least_3(mode1: int, value: int, stored: int) -> None:
    board = Pca9685Model()
    board.write([0x00, mode1])
    board.write([0xFE, value])
    assert board.prescale == stored


# --- RESTART (datasheet §7.3.1.1) ---


def test_sleeping_with_a_channel_running_sets_restart_and_stops_the_output() -> None:
    board = running(channel=5)
    assert board.pulse_us(5) > 0
    board.write([0x00, AI | SLEEP])
    assert board.register(0x00) == RESTART | AI | SLEEP
    assert board.halted
    assert board.pulse_us(5) == 0.0
    board.write([0x00, AI])  # awake again, but the channel waits for the restart
    assert board.running
    assert board.halted
    assert board.pulse_us(5) == 0.0
    assert board.violations == []


def test_sleeping_with_every_channel_full_off_leaves_restart_clear() -> None:
    board = running(channel=2)
    board.write([0xFD, 0x10])  # orderly shutdown: ALL_LED_OFF_H full off
    board.write([0x00, AI | SLEEP])
    assert not board.halted
    assert board.register(0x00) == AI | SLEEP


RESTART_CASES = [
    # (µs between clearing SLEEP and writing RESTART, RESTART cleared, violation)
    (500.0, True, False),
    (5000.0, True, False),
    (499.0, False, True),
    (0.0, False, True),
]


@pytest.mark.parametrize(("wait_us", "cleared", "violation"), RESTART_CASES)
def test_restart_is_honoured_only_500_us_after_waking(wait_us: float, cleared: bool, violation: bool) -> None:
    board = running(channel=0, off=300)
    board.write([0x00, AI | SLEEP])
    board.write([0x00, AI])
    board.clock.advance(wait_us * 1e-6)
    board.write([0x00, RESTART | AI])
    assert board.halted is not cleared
    assert bool(board.violations) is violation
    assert board.pulse_us(0) == (pytest.approx(300 * board.period_us / 4096) if cleared else 0.0)


def test_restart_in_the_same_write_that_wakes_is_a_violation() -> None:
    board = running()
    board.write([0x00, AI | SLEEP])
    board.clock.advance(1.0)
    board.write([0x00, RESTART | AI])
    assert board.halted
    assert board.violations
    assert "0 µs" in board.violations[0]


def test_restart_written_while_asleep_is_a_violation() -> None:
    board = Pca9685Model()
    board.write([0x00, RESTART | SLEEP])
    assert board.violations == ["RESTART written while SLEEP is 1 (datasheet §7.3.1.1)"]


def test_writing_0_to_restart_has_no_effect() -> None:
    board = running()
    board.write([0x00, AI | SLEEP])
    board.write([0x00, AI])
    board.clock.advance(1e-3)
    board.write([0x00, AI])
    assert board.halted
    assert board.violations == []


def test_a_pwm_register_write_clears_restart_when_outputs_change_on_stop() -> None:
    board = running()
    board.write([0x00, AI | SLEEP])
    board.write([0x00, AI])
    board.clock.advance(1e-3)
    board.write([0x0A, 0, 0, 100, 0])
    assert not board.halted
    assert board.pulse_us(0) > 0
    assert board.pulse_us(1) > 0


def test_with_och_only_a_whole_channel_write_clears_restart() -> None:
    board = running()
    board.write([0x01, 0x04 | 0x08])  # MODE2: OCH, outputs change on ACK
    board.write([0x00, AI | SLEEP])
    board.write([0x00, AI])
    board.clock.advance(1e-3)
    board.write([0x0C, 100])
    assert board.halted
    board.write([0x0A, 0, 0, 100, 0])
    assert not board.halted


def test_pwm_registers_written_while_the_oscillator_settles_is_a_violation() -> None:
    board = Pca9685Model()
    board.write([0x00, AI])
    board.clock.advance(100e-6)
    board.write([0x06, 0, 0, 100, 0])
    assert board.violations == [
        "PWM registers written while the oscillator settles (datasheet §7.3.1, note 2)"
    ]


def test_extclk_is_not_expected() -> None:
    board = Pca9685Model()
    board.write([0x00, SLEEP | 0x40])
    board.write([0x00, SLEEP])
    assert board.register(0x00) & 0x40  # sticky
    assert len(board.violations) == 1


# --- ALL_LED (datasheet §7.3.4) ---


def test_all_led_writes_every_channel_and_reads_zero() -> None:
    board = awake()
    board.write([0xFA, 0x01, 0x02, 0x03, 0x04])
    assert board.channels() == [Channel(0x201, 0x403, False, False)] * 16
    board.write([0xFA])
    assert board.read(4) == bytes(4)
    board.write([0xFD, 0xF0])  # bits 7..5 are dropped as in every LEDn_OFF_H
    assert board.channels() == [Channel(0x201, 0x003, False, True)] * 16
    assert board.led_registers == bytes([0x01, 0x02, 0x03, 0x10]) * 16


# --- the output (datasheet §7.3.3) ---

PULSE_CASES = [
    # (ON_H full bit, OFF_H full bit, on, off, counts high) at PRE_SCALE 30 (200 Hz)
    (0, 0, 0, 307, 307),
    (0, 0, 409, 1228, 819),  # datasheet example 1: 10 % delay, 20 % duty
    (0, 0, 3686, 409, 819),  # example 2: 90 % delay, 20 % duty, wrapping round
    (0, 0, 0, 4095, 4095),
    (0x10, 0, 0, 0, 4096),  # full on
    (0x10, 0, 100, 200, 4096),  # full on ignores OFF
    (0, 0x10, 0, 2000, 0),  # full off
    (0x10, 0x10, 0, 2000, 0),  # full off wins over full on
]


@pytest.mark.parametrize(("on_full", "off_full", "on", "off", "counts"), PULSE_CASES)
def test_pulse_from_the_channel_registers(
    on_full: int, off_full: int, on: int, off: int, counts: int
) -> None:
    board = awake()
    board.write([0x0E, on & 0xFF, on >> 8 | on_full, off & 0xFF, off >> 8 | off_full])
    period_us = 31 * 4096 / 25e6 * 1e6
    assert board.period_us == pytest.approx(period_us)
    assert board.pulse_us(2) == pytest.approx(counts * period_us / 4096)
    assert board.violations == []


@pytest.mark.parametrize(
    ("prescale", "oscillator_hz", "period_us"),
    [(121, 25e6, 19988.48), (3, 25e6, 655.36), (255, 25e6, 41943.04), (121, 26.6e6, 18786.165413533834)],
)
def test_period_from_prescale_and_oscillator(prescale: int, oscillator_hz: float, period_us: float) -> None:
    board = Pca9685Model(oscillator_hz=oscillator_hz)
    board.write([0xFE, prescale])
    assert board.period_us == pytest.approx(period_us)


def test_on_equal_to_off_is_a_violation_and_makes_no_pulse() -> None:
    board = awake()
    board.write([0x06, 0, 0, 0, 0])
    assert board.pulse_us(0) == 0.0
    assert board.violations == ["LED0_ON == LED0_OFF == 0 (datasheet §7.3.4: never)"]


# --- the smbus2-shaped bus ---


def test_bus_routes_by_address_and_logs() -> None:
    bus = FakeSmbus.with_boards([0x40, 0x41])
    bus.write_byte_data(0x41, 0x00, AI)
    bus.write_i2c_block_data(0x41, 0x00, [AI | SLEEP, 0x04])
    assert bus.read_byte_data(0x41, 0x00) == AI | SLEEP
    assert bus.read_i2c_block_data(0x41, 0x00, 2) == [AI | SLEEP, 0x04]
    assert bus.boards[0x40].register(0x00) == 0x11
    assert bus.log[:2] == [
        Transfer("write_byte", 0x41, bytes([0x00, AI])),
        Transfer("write_block", 0x41, bytes([0x00, AI | SLEEP, 0x04])),
    ]
    assert (bus.count("write_block"), bus.count("read_byte"), bus.count("read_block")) == (1, 1, 1)


def test_bus_refuses_unknown_addresses_and_long_blocks() -> None:
    bus = FakeSmbus.with_boards([0x40])
    with pytest.raises(OSError, match="0x42") as raised:
        bus.write_byte_data(0x42, 0x00, 0)
    assert raised.value.errno == errno.ENXIO
    with pytest.raises(ValueError, match="32"):
        bus.write_i2c_block_data(0x40, 0x06, [0] * 33)
    bus.write_i2c_block_data(0x40, 0x06, [0] * 32)
    assert bus.count("write_block") == 1


@pytest.mark.parametrize("code", [errno.EIO, errno.ENODEV, errno.EREMOTEIO])
def test_bus_fails_the_next_operations_then_heals(code: int) -> None:
    bus = FakeSmbus.with_boards([0x40])
    bus.fail(code, times=2, after=1)
    bus.write_byte_data(0x40, 0x01, 0x04)
    for _ in range(2):
        with pytest.raises(OSError, match=os.strerror(code)) as raised:
            bus.write_byte_data(0x40, 0x01, 0x05)
        assert raised.value.errno == code
    bus.write_byte_data(0x40, 0x01, 0x06)
    assert bus.failures == 2
    assert bus.boards[0x40].register(0x01) == 0x06


def test_bus_fails_until_healed_and_refuses_when_closed() -> None:
    bus = FakeSmbus.with_boards([0x40])
    bus.fail(errno.ENODEV)
    for _ in range(5):
        with pytest.raises(OSError, match="No such device"):
            bus.read_byte_data(0x40, 0x00)
    bus.heal()
    assert bus.read_byte_data(0x40, 0x00) == 0x11
    bus.close()
    with pytest.raises(OSError, match="closed") as raised:
        bus.read_byte_data(0x40, 0x00)
    assert raised.value.errno == errno.EBADF
    assert bus.open(1) is bus
    assert (bus.opened, bus.closes) == ([1], 1)
    assert bus.read_byte_data(0x40, 0x00) == 0x11


def test_all_call_reaches_every_board_with_allcall_on() -> None:
    bus = FakeSmbus.with_boards([0x40, 0x41, 0x42])
    bus.write_byte_data(0x42, 0x00, AI)  # all-call off on 0x42 only
    bus.write_byte_data(0x70, 0x01, 0x05)  # 0xE0 >> 1
    assert [bus.boards[a].register(0x01) for a in (0x40, 0x41, 0x42)] == [0x05, 0x05, 0x04]
    with pytest.raises(DatasheetError, match="2 boards"):
        bus.read_byte_data(0x70, 0x00)


# --- the busio.I2C-shaped adapter ---


def test_busio_adapter_writes_reads_and_needs_the_lock() -> None:
    bus = FakeSmbus.with_boards([0x40])
    i2c = BusioI2C(bus)
    with pytest.raises(RuntimeError):
        i2c.writeto(0x40, b"\x00\x20")
    assert i2c.try_lock()
    assert not i2c.try_lock()
    i2c.writeto(0x40, b"xx\x00\x20yy", start=2, end=4)
    buffer = bytearray(3)
    i2c.writeto_then_readfrom(0x40, b"\x00", buffer, in_start=1)
    assert buffer == bytearray([0, AI, 0x04])  # auto-increment: MODE1, then MODE2
    assert i2c.scan() == [0x40]
    i2c.writeto(0x40, b"")  # a probe: the address is acknowledged, nothing changes
    with pytest.raises(OSError, match="0x41"):
        i2c.writeto(0x41, b"")
    i2c.unlock()
    assert bus.boards[0x40].violations == []
