"""A PCA9685 written from NXP's datasheet (PCA9685 product data sheet, rev. 4), to judge what a driver
puts on the bus: the register file with its power-on values, the control register (the pointer) and
auto-increment, PRE_SCALE taking writes only while asleep, the RESTART rules, the ALL_LED registers and
the pulse each channel's registers make. With it: an smbus2-shaped bus holding several boards by
address, and a busio.I2C-shaped adapter so that Adafruit's driver can drive the same boards.

Every number here is restated from the datasheet on purpose (nothing comes from urdaemon.boards): the
model is a second, independent statement of the chip, so a wrong constant there shows up here.

Where the datasheet leaves behaviour open, the model takes the strict reading and says so:
- a channel that ran when SLEEP was set stays stopped after waking until RESTART is written (or a PWM
  register write clears RESTART), so a driver that forgets the restart sees no pulse;
- accesses the datasheet forbids (reserved registers, TestMode) raise ``DatasheetError``; accesses it
  warns about (RESTART too early, PWM registers written while the oscillator settles, ON == OFF) are
  recorded in ``violations``, which tests check is empty.
"""

from __future__ import annotations

import errno
import os
from collections.abc import Iterable, Mapping, Sequence
from typing import NamedTuple

__all__ = [
    "OSCILLATOR_HZ",
    "BusioI2C",
    "Channel",
    "DatasheetError",
    "FakeSmbus",
    "ModelClock",
    "Pca9685Model",
    "Transfer",
]

OSCILLATOR_HZ = 25_000_000.0
"""The internal oscillator (datasheet §7.3.5: 25 MHz)."""
COUNTS = 4096
"""Counts per PWM period: the 12-bit counter (datasheet §7.3.3)."""
SETTLE_NS = 500_000
"""The oscillator needs up to 500 µs after SLEEP goes to 0 (datasheet §7.3.1 MODE1 note 2 and
datasheet §7.3.1.1)."""
SMBUS_BLOCK_MAX = 32
"""The most data bytes one SMBus block transfer carries (smbus2 and the kernel refuse more)."""

# datasheet §7.3, register summary
MODE1, MODE2 = 0x00, 0x01
SUBADR1, SUBADR2, SUBADR3, ALLCALLADR = 0x02, 0x03, 0x04, 0x05
LED0_ON_L, LED15_OFF_H = 0x06, 0x45
ALL_LED_ON_L, ALL_LED_OFF_H = 0xFA, 0xFD
PRE_SCALE, TEST_MODE = 0xFE, 0xFF

# datasheet §7.3.1, MODE1 bits
RESTART, EXTCLK, AI, SLEEP = 0x80, 0x40, 0x20, 0x10
SUB1, SUB2, SUB3, ALLCALL = 0x08, 0x04, 0x02, 0x01
# datasheet §7.3.2, MODE2 bits: OCH = outputs change on ACK (1) or on STOP (0)
OCH = 0x08
# datasheet §7.3.3: bit 4 of LEDn_ON_H is full on, bit 4 of LEDn_OFF_H full off;
# bits 7..5 read 0 and cannot be written
FULL = 0x10
HIGH_MASK = 0x1F

POWER_ON = {
    MODE1: SLEEP | ALLCALL,
    MODE2: 0x04,
    SUBADR1: 0xE2,
    SUBADR2: 0xE4,
    SUBADR3: 0xE8,
    ALLCALLADR: 0xE0,
    PRE_SCALE: 0x1E,
}
"""Registers whose power-on value is not 0 (besides every LEDn_OFF_H, which starts at full off)."""
PRESCALE_MIN = 3
"""datasheet §7.3.5: the hardware forces PRE_SCALE values below 3 to 3."""


class DatasheetError(Exception):
    """An access the datasheet forbids (a reserved register, TestMode, several boards answering one
    read): the driver under test is wrong. Not an OSError, so no driver's error handling swallows it."""


class Channel(NamedTuple):
    """One channel's registers, decoded: the ON and OFF counts and the full-on / full-off bits."""

    on: int
    off: int
    full_on: bool
    full_off: bool


class ModelClock:
    """Time as the boards see it, in whole nanoseconds; ``advance`` stands in for ``time.sleep``."""

    def __init__(self) -> None:
        self.now_ns = 0

    def advance(self, seconds: float) -> None:
        """Let ``seconds`` pass."""
        if seconds < 0:
            raise ValueError(f"time does not run backwards ({seconds} s)")
        self.now_ns += round(seconds * 1e9)


def _reserved(register: int) -> bool:
    return LED15_OFF_H < register < ALL_LED_ON_L or register == TEST_MODE


def _next(register: int) -> int:
    """The pointer after ``register`` with auto-increment: past LED15_OFF_H and past PRE_SCALE it rolls
    over to MODE1 (datasheet §7.3, remark under the register summary)."""
    return MODE1 if register in (LED15_OFF_H, PRE_SCALE) else register + 1


class Pca9685Model:
    """One PCA9685 as its registers and oscillator; ``write``/``read`` are single I²C transfers."""

    def __init__(self, clock: ModelClock | None = None, oscillator_hz: float = OSCILLATOR_HZ) -> None:
        self.clock = clock if clock is not None else ModelClock()
        self.oscillator_hz = oscillator_hz
        self.violations: list[str] = []
        """What the driver did that the datasheet warns against, in words."""
        self._registers = bytearray(256)
        self._pointer = 0
        self._awake_since_ns: int | None = None
        self.power_on()

    def power_on(self) -> None:
        """The state after power-on reset: defaults, pointer at MODE1, asleep."""
        self._registers[:] = bytes(256)
        for register, value in POWER_ON.items():
            self._registers[register] = value
        for channel in range(16):
            self._registers[LED0_ON_L + 4 * channel + 3] = FULL
        self._pointer = MODE1
        self._awake_since_ns = None

    # --- the bus side ---

    def write(self, data: bytes | Sequence[int]) -> None:
        """One write transfer after the address byte, ending in STOP: the control register (the
        pointer), then data bytes; an empty write only has the address acknowledged."""
        data = bytes(data)
        if not data:
            return
        self._pointer = self._check(data[0])
        pwm_written: set[int] = set()
        for value in data[1:]:
            register = self._check(self._pointer)
            pwm_written |= self._store(register, value)
            if self._registers[MODE1] & AI:
                self._pointer = _next(register)
        if pwm_written:
            self._pwm_written(pwm_written)

    def read(self, count: int) -> bytes:
        """One read transfer of ``count`` bytes from the pointer; ALL_LED registers read as 0."""
        out = bytearray()
        for _ in range(count):
            register = self._check(self._pointer)
            out.append(0 if ALL_LED_ON_L <= register <= ALL_LED_OFF_H else self._registers[register])
            if self._registers[MODE1] & AI:
                self._pointer = _next(register)
        return bytes(out)

    def answers_call(self, address: int) -> bool:
        """True when the board answers ``address`` as its LED All Call or an enabled Sub Call address
        (the registers hold the 8-bit form: the 7-bit address shifted left once)."""
        mode1 = self._registers[MODE1]
        calls = [(ALLCALL, ALLCALLADR), (SUB1, SUBADR1), (SUB2, SUBADR2), (SUB3, SUBADR3)]
        return any(mode1 & bit and self._registers[reg] >> 1 == address for bit, reg in calls)

    # --- what tests look at ---

    def register(self, register: int) -> int:
        """A register's stored value, looked at without a bus access (no pointer move, no checks)."""
        return self._registers[register]

    @property
    def led_registers(self) -> bytes:
        """LED0_ON_L..LED15_OFF_H, 64 bytes."""
        return bytes(self._registers[LED0_ON_L : LED15_OFF_H + 1])

    @property
    def running(self) -> bool:
        """The oscillator is on (SLEEP is 0)."""
        return not self._registers[MODE1] & SLEEP

    @property
    def halted(self) -> bool:
        """RESTART is 1: the channels that ran before the sleep wait for a restart."""
        return bool(self._registers[MODE1] & RESTART)

    @property
    def prescale(self) -> int:
        """PRE_SCALE as stored."""
        return self._registers[PRE_SCALE]

    @property
    def period_us(self) -> float:
        """The PWM period: (PRE_SCALE + 1) × 4096 oscillator cycles (datasheet §7.3.5, equation 1
        turned round)."""
        return (self.prescale + 1) * COUNTS / self.oscillator_hz * 1e6

    def channels(self) -> list[Channel]:
        """All 16 channels, decoded."""
        return [self._channel(n) for n in range(16)]

    def pulse_us(self, channel: int) -> float:
        """The high time per period the output makes now (µs): 0 when full off, asleep or halted,
        the whole period when full on, else (OFF − ON) mod 4096 counts (datasheet §7.3.3, both
        delay cases)."""
        if not self.running or self.halted:
            return 0.0
        state = self._channel(channel)
        if state.full_off:
            return 0.0
        if state.full_on:
            return self.period_us
        return (state.off - state.on) % COUNTS * self.period_us / COUNTS

    # --- the rules ---

    def _check(self, register: int) -> int:
        if _reserved(register):
            raise DatasheetError(
                f"register 0x{register:02x} is reserved (datasheet §7.3); no driver may touch it"
            )
        return register

    def _channel(self, channel: int) -> Channel:
        base = LED0_ON_L + 4 * channel
        on_l, on_h, off_l, off_h = self._registers[base : base + 4]
        return Channel(
            on_l | (on_h & 0x0F) << 8, off_l | (off_h & 0x0F) << 8, bool(on_h & FULL), bool(off_h & FULL)
        )

    def _store(self, register: int, value: int) -> set[int]:
        """Store one data byte; the PWM registers it wrote (for the STOP rules)."""
        if register == MODE1:
            self._write_mode1(value)
        elif register == MODE2:
            self._registers[MODE2] = value & 0x1F  # bits 7..5 reserved, read only
        elif SUBADR1 <= register <= ALLCALLADR:
            self._registers[register] = value & 0xFE  # bit 0 read only
        elif LED0_ON_L <= register <= LED15_OFF_H:
            high = (register - LED0_ON_L) % 2 == 1
            self._registers[register] = value & HIGH_MASK if high else value
            return {register}
        elif ALL_LED_ON_L <= register <= ALL_LED_OFF_H:
            offset = register - ALL_LED_ON_L
            written = {LED0_ON_L + 4 * channel + offset for channel in range(16)}
            for target in written:
                self._registers[target] = value & HIGH_MASK if offset % 2 else value
            return written
        elif register == PRE_SCALE and self._registers[MODE1] & SLEEP:
            self._registers[PRE_SCALE] = max(value, PRESCALE_MIN)
        # PRE_SCALE while awake: the write is blocked (datasheet §7.3, register summary note 1)
        return set()

    def _write_mode1(self, value: int) -> None:
        now = self.clock.now_ns
        old = self._registers[MODE1]
        new = (old & (RESTART | EXTCLK)) | (value & ~RESTART & 0xFF)
        if value & EXTCLK and not old & EXTCLK:
            self.violations.append("EXTCLK set: these boards run on the internal oscillator (it is sticky)")
        if not old & SLEEP and value & SLEEP:
            self._awake_since_ns = None
            if any(not state.full_off for state in self.channels()):
                new |= RESTART  # datasheet §7.3.1.1: put to sleep with channels running
        elif old & SLEEP and not value & SLEEP:
            self._awake_since_ns = now
        self._registers[MODE1] = new
        if not value & RESTART:
            return  # writing 0 to RESTART has no effect
        if self._awake_since_ns is None:
            self.violations.append("RESTART written while SLEEP is 1 (datasheet §7.3.1.1)")
        elif now - self._awake_since_ns < SETTLE_NS:
            waited = (now - self._awake_since_ns) / 1000
            self.violations.append(
                f"RESTART written {waited:g} µs after SLEEP was cleared (datasheet §7.3.1.1: ≥ 500)"
            )
        else:
            self._registers[MODE1] = new & ~RESTART

    def _pwm_written(self, registers: set[int]) -> None:
        """The STOP (end of a write) after PWM registers were written."""
        if self._awake_since_ns is not None and self.clock.now_ns - self._awake_since_ns < SETTLE_NS:
            self.violations.append(
                "PWM registers written while the oscillator settles (datasheet §7.3.1, note 2)"
            )
        channels = sorted({(r - LED0_ON_L) // 4 for r in registers})
        whole = [c for c in channels if all(LED0_ON_L + 4 * c + k in registers for k in range(4))]
        if not self._registers[MODE2] & OCH or whole:  # datasheet §7.3.1.1: other actions that clear RESTART
            self._registers[MODE1] &= ~RESTART
        for channel in channels:
            state = self._channel(channel)
            if not state.full_on and not state.full_off and state.on == state.off:
                self.violations.append(
                    f"LED{channel}_ON == LED{channel}_OFF == {state.on} (datasheet §7.3.4: never)"
                )


class Transfer(NamedTuple):
    """One bus operation as logged: its kind, the address, and the bytes after the address (for
    writes the pointer first; for reads the pointer written before, then what came back)."""

    kind: str
    address: int
    data: bytes


class FakeSmbus:
    """An ``smbus2.SMBus``-shaped bus with PCA9685 models on it by address."""

    def __init__(self, boards: Mapping[int, Pca9685Model]) -> None:
        self.boards = dict(boards)
        self.log: list[Transfer] = []
        """Every operation that reached the boards, in order."""
        self.opened: list[int] = []
        """The bus numbers ``open`` was called with."""
        self.closes = 0
        self.failures = 0
        """Operations refused by ``fail``."""
        self.is_open = True
        self._fail_code = 0
        self._fail_after = 0
        self._fail_left: int | None = None

    @classmethod
    def with_boards(
        cls, addresses: Iterable[int], clock: ModelClock | None = None, oscillator_hz: float = OSCILLATOR_HZ
    ) -> FakeSmbus:
        """A bus with a fresh board at each address, all on one clock."""
        clock = clock if clock is not None else ModelClock()
        return cls({address: Pca9685Model(clock, oscillator_hz) for address in addresses})

    def open(self, bus: int) -> FakeSmbus:
        """Open the bus again (for ``open_bus=``): records ``bus`` and returns this bus."""
        self.opened.append(bus)
        self.is_open = True
        return self

    def fail(self, code: int = errno.EIO, *, times: int | None = None, after: int = 0) -> None:
        """Make operations raise ``OSError(code)``: ``after`` more succeed first, then ``times`` fail
        (None: all fail until ``heal``)."""
        self._fail_code, self._fail_after, self._fail_left = code, after, times

    def heal(self) -> None:
        """Operations succeed again."""
        self._fail_code = 0

    def count(self, kind: str) -> int:
        """Logged operations of ``kind`` (``write_block``, ``write_byte``, ...)."""
        return sum(1 for transfer in self.log if transfer.kind == kind)

    # --- smbus2's calls ---

    def write_byte_data(self, i2c_addr: int, register: int, value: int) -> None:
        """SMBus write byte: the pointer, then one byte."""
        self.send(i2c_addr, _bytes([register, value]), "write_byte")

    def read_byte_data(self, i2c_addr: int, register: int) -> int:
        """SMBus read byte: the pointer written, then one byte read."""
        return self.send_then_receive(i2c_addr, _bytes([register]), 1, "read_byte")[0]

    def write_i2c_block_data(self, i2c_addr: int, register: int, data: Sequence[int]) -> None:
        """I²C block write: the pointer, then up to 32 bytes (smbus2 raises ValueError for more)."""
        if len(data) > SMBUS_BLOCK_MAX:
            raise ValueError(f"Data length cannot exceed {SMBUS_BLOCK_MAX} bytes")
        self.send(i2c_addr, _bytes([register, *data]), "write_block")

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int) -> list[int]:
        """I²C block read of up to 32 bytes from ``register``."""
        if length > SMBUS_BLOCK_MAX:
            raise ValueError(f"Desired block length over {SMBUS_BLOCK_MAX} bytes")
        return list(self.send_then_receive(i2c_addr, _bytes([register]), length, "read_block"))

    def close(self) -> None:
        """Close the device file (an armed failure makes this raise too)."""
        self.closes += 1
        self.is_open = False
        self._refused()

    # --- raw transfers (the busio adapter's too) ---

    def send(self, address: int, data: bytes, kind: str = "write") -> None:
        """One write transfer to every board answering ``address``."""
        self._begin()
        for board in self._targets(address):
            board.write(data)
        self.log.append(Transfer(kind, address, data))

    def receive(self, address: int, count: int) -> bytes:
        """One read transfer from the board at ``address``."""
        self._begin()
        data = self._reader(address).read(count)
        self.log.append(Transfer("read", address, data))
        return data

    def send_then_receive(self, address: int, out: bytes, count: int, kind: str = "write_read") -> bytes:
        """A write then a read after a repeated START (one operation)."""
        self._begin()
        board = self._reader(address)
        board.write(out)
        data = board.read(count)
        self.log.append(Transfer(kind, address, out + data))
        return data

    def _begin(self) -> None:
        if not self.is_open:
            raise OSError(errno.EBADF, "the bus is closed")
        self._refused()

    def _refused(self) -> None:
        if not self._fail_code:
            return
        if self._fail_after > 0:
            self._fail_after -= 1
            return
        code = self._fail_code
        if self._fail_left is not None:
            self._fail_left -= 1
            if self._fail_left <= 0:
                self._fail_code = 0
        self.failures += 1
        raise OSError(code, os.strerror(code))

    def _targets(self, address: int) -> list[Pca9685Model]:
        if not 0 <= address <= 0x7F:
            raise ValueError(f"0x{address:x} is not a 7-bit I²C address")
        targets = [b for a, b in self.boards.items() if a == address or b.answers_call(address)]
        if not targets:
            raise OSError(errno.ENXIO, f"no device answers at 0x{address:02x}")
        return targets

    def _reader(self, address: int) -> Pca9685Model:
        targets = self._targets(address)
        if len(targets) > 1:
            raise DatasheetError(f"{len(targets)} boards answer a read at 0x{address:02x}")
        return targets[0]


def _bytes(values: Sequence[int]) -> bytes:
    if not all(0 <= v <= 0xFF for v in values):
        raise ValueError(f"not bytes: {list(values)}")
    return bytes(values)


class BusioI2C:
    """The part of ``busio.I2C`` that ``adafruit_bus_device.I2CDevice`` calls (its probe included:
    an empty write, then a one-byte read), over a ``FakeSmbus``'s boards."""

    def __init__(self, bus: FakeSmbus) -> None:
        self._bus = bus
        self.locked = False

    def try_lock(self) -> bool:
        """Take the bus lock if it is free."""
        if self.locked:
            return False
        self.locked = True
        return True

    def unlock(self) -> None:
        """Release the bus lock."""
        if not self.locked:
            raise RuntimeError("unlock without the lock")
        self.locked = False

    def writeto(
        self, address: int, buffer: bytes | bytearray | memoryview, *, start: int = 0, end: int | None = None
    ) -> None:
        """Write ``buffer[start:end]`` to ``address`` (then STOP)."""
        self._held()
        self._bus.send(address, bytes(buffer[start:end]))

    def readfrom_into(
        self, address: int, buffer: bytearray | memoryview, *, start: int = 0, end: int | None = None
    ) -> None:
        """Read into ``buffer[start:end]`` from ``address``."""
        self._held()
        end = len(buffer) if end is None else end
        buffer[start:end] = self._bus.receive(address, end - start)

    def writeto_then_readfrom(
        self,
        address: int,
        buffer_out: bytes | bytearray | memoryview,
        buffer_in: bytearray | memoryview,
        *,
        out_start: int = 0,
        out_end: int | None = None,
        in_start: int = 0,
        in_end: int | None = None,
    ) -> None:
        """Write ``buffer_out[out_start:out_end]``, then (repeated START) read into
        ``buffer_in[in_start:in_end]``."""
        self._held()
        out = bytes(buffer_out[out_start:out_end])
        in_end = len(buffer_in) if in_end is None else in_end
        buffer_in[in_start:in_end] = self._bus.send_then_receive(address, out, in_end - in_start)

    def scan(self) -> list[int]:
        """The addresses that answer (each board's own)."""
        self._held()
        return sorted(self._bus.boards)

    def _held(self) -> None:
        if not self.locked:
            raise RuntimeError("busio.I2C used without try_lock()")
