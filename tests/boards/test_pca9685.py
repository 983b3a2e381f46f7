"""urdaemon.boards.pca9685, the pure part of the PCA9685 output: prescale and count formulas, the
start-up writes and the block writes between two images of a board's channels. Expected numbers are
the datasheet's (NXP PCA9685 rev. 4, datasheet §7.3.5 equation 1 and its 200 Hz example), written out here."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.boards.pca9685_model import Pca9685Model
from urdaemon.boards import pca9685
from urdaemon.boards.pca9685 import (
    FULL_OFF,
    block_writes,
    channel_bytes,
    count_for,
    frequency_of,
    prescale_for,
    startup_writes,
)

# --- prescale_for / frequency_of ---

PRESCALES = [
    # (output Hz, oscillator Hz, PRE_SCALE): round(osc / (4096 × f)) − 1
    (200.0, 25e6, 0x1E),  # the datasheet's example (and the power-on value)
    (50.0, 25e6, 121),  # 122.07 → 122
    (60.0, 25e6, 101),  # 101.73 → 102
    (330.0, 25e6, 17),  # 18.495 → 18
    (24.0, 25e6, 253),  # 254.31 → 254: the low end of the datasheet's range
    (1526.0, 25e6, 3),  # 3.9997 → 4: the high end
    (23.85, 25e6, 255),  # 255.91 → 256: the slowest the chip makes
    (50.0, 26.6e6, 129),  # 129.88 → 130: a board whose oscillator runs fast
    (50.0, 24e6, 116),  # 117.19 → 117
]


@pytest.mark.parametrize(("frequency_hz", "oscillator_hz", "prescale"), PRESCALES)
def test_prescale_for_follows_equation_1(frequency_hz: float, oscillator_hz: float, prescale: int) -> None:
    assert prescale_for(frequency_hz, oscillator_hz) == prescale


def test_prescale_for_defaults_to_the_25_mhz_oscillator() -> None:
    assert prescale_for(50.0) == 121
    assert frequency_of(121) == pytest.approx(25e6 / (4096 * 122))


@pytest.mark.parametrize(
    ("frequency_hz", "oscillator_hz"),
    [
        (23.0, 25e6),  # PRE_SCALE 264
        (1800.0, 25e6),  # PRE_SCALE 2
        (24.0, 28e6),  # 284.8 → 284: the fast oscillator cannot go that slow
        (0.0, 25e6),
        (-50.0, 25e6),
        (math.nan, 25e6),
        (math.inf, 25e6),
        (50.0, 0.0),
    ],
)
def test_prescale_for_refuses_what_the_chip_cannot_make(frequency_hz: float, oscillator_hz: float) -> None:
    with pytest.raises(ValueError, match="PCA9685"):
        prescale_for(frequency_hz, oscillator_hz)


@settings(max_examples=200, deadline=None)
@given(frequency_hz=st.floats(24.0, 1526.0))
def test_every_frequency_of_the_datasheets_range_has_a_prescale(frequency_hz: float) -> None:
    check_nearest_period(frequency_hz, 25e6)


@settings(max_examples=200, deadline=None)
@given(oscillator_hz=st.floats(20e6, 30e6), share=st.floats(0.0, 1.0))
def test_frequency_of_prescale_for_is_the_nearest_period(oscillator_hz: float, share: float) -> None:
    slowest, fastest = oscillator_hz / (4096 * 255.4), oscillator_hz / (4096 * 3.6)
    check_nearest_period(slowest + share * (fastest - slowest), oscillator_hz)


def check_nearest_period(frequency_hz: float, oscillator_hz: float) -> None:
    """PRE_SCALE + 1 is the whole number of 4096-cycle steps nearest the requested period."""
    prescale = prescale_for(frequency_hz, oscillator_hz)
    ideal = oscillator_hz / (4096 * frequency_hz)  # PRE_SCALE + 1 for exactly f
    assert abs(prescale + 1 - ideal) <= 0.5 + 1e-9
    real = frequency_of(prescale, oscillator_hz)
    assert real == pytest.approx(oscillator_hz / (4096 * (prescale + 1)))
    assert abs(real - frequency_hz) / frequency_hz <= 0.5 / (prescale + 1) + 1e-9
    assert prescale_for(real, oscillator_hz) == prescale  # the real frequency maps to itself


# --- count_for ---

COUNTS = [
    # (pulse µs, PRE_SCALE, oscillator Hz, count): pulse / period × 4096 rounded,
    # where period = (PRE_SCALE + 1) × 4096 / osc
    (1500.0, 121, 25e6, 307),  # 307.38
    (1000.0, 121, 25e6, 205),  # 204.92
    (2000.0, 121, 25e6, 410),  # 409.84
    (500.0, 121, 25e6, 102),  # 102.46
    (1500.0, 129, 26.6e6, 307),  # 306.92
    (1500.0, 17, 25e6, 2083),  # 2083.33
    (1000.0, 3, 25e6, 4095),  # longer than the 655.36 µs period: clamped
    (3.0, 121, 25e6, 1),  # 0.61
    (2.0, 121, 25e6, 0),  # 0.41
    (0.0, 121, 25e6, 0),
    (-10.0, 121, 25e6, 0),
    (19990.0, 121, 25e6, 4095),  # a whole period and more: clamped to 4095
    (1e9, 121, 25e6, 4095),
]


@pytest.mark.parametrize(("pulse_us", "prescale", "oscillator_hz", "count"), COUNTS)
def test_count_for_rounds_and_clamps(
    pulse_us: float, prescale: int, oscillator_hz: float, count: int
) -> None:
    assert count_for(pulse_us, prescale, oscillator_hz) == count


@settings(max_examples=200, deadline=None)
@given(
    pulse_us=st.floats(0.0, 40000.0),
    prescale=st.integers(3, 255),
    oscillator_hz=st.floats(20e6, 30e6),
)
def test_count_for_is_the_nearest_count(pulse_us: float, prescale: int, oscillator_hz: float) -> None:
    count = count_for(pulse_us, prescale, oscillator_hz)
    exact = pulse_us * oscillator_hz / ((prescale + 1) * 1e6)  # the pulse in oscillator cycles / (p + 1)
    assert 0 <= count <= 4095
    if 0.5 <= exact <= 4094.5:
        assert abs(count - exact) <= 0.5 + 1e-6
    else:
        assert count == (0 if exact < 0.5 else 4095)


# --- channel_bytes ---


@pytest.mark.parametrize(
    ("count", "data"),
    [
        (307, bytes([0, 0, 0x33, 0x01])),
        (4095, bytes([0, 0, 0xFF, 0x0F])),
        (1, bytes([0, 0, 1, 0])),
        (FULL_OFF, bytes([0, 0, 0, 0x10])),
    ],
)
def test_channel_bytes_are_on_l_on_h_off_l_off_h(count: int, data: bytes) -> None:
    assert channel_bytes(count) == data


def test_count_0_is_written_as_full_off() -> None:
    assert channel_bytes(0) == bytes([0, 0, 0, 0x10])


# --- startup_writes ---


@pytest.mark.parametrize("prescale", [3, 30, 121, 255])
def test_startup_writes_sleep_prescale_mode2_wake_then_restart(prescale: int) -> None:
    until_wake, after_settle = startup_writes(prescale)
    assert until_wake == [(0x00, 0x10), (0xFE, prescale), (0x01, 0x04), (0x00, 0x20)]
    assert after_settle == [(0x00, 0xA0)]
    assert pca9685.OSCILLATOR_SETTLE_S == 500e-6


@pytest.mark.parametrize("prescale", [-1, 0, 2, 256])
def test_startup_writes_refuse_a_prescale_the_chip_would_change(prescale: int) -> None:
    with pytest.raises(ValueError, match="PRE_SCALE"):
        startup_writes(prescale)


@pytest.mark.parametrize("was_running", [False, True])
def test_startup_writes_bring_the_model_up_without_a_violation(was_running: bool) -> None:
    board = Pca9685Model()
    if was_running:  # a board left pulsing by an earlier run
        board.write([0x00, 0x20])
        board.clock.advance(1e-3)
        board.write([0x06, 0, 0, 0x33, 0x01])
    until_wake, after_settle = startup_writes(121)
    for register, value in until_wake:
        board.write([register, value])
    board.clock.advance(pca9685.OSCILLATOR_SETTLE_S)
    for register, value in after_settle:
        board.write([register, value])
    assert (board.register(0x00), board.register(0x01), board.prescale) == (0x20, 0x04, 121)
    assert board.running
    assert not board.halted
    assert board.violations == []
    assert board.pulse_us(0) == (pytest.approx(307 * board.period_us / 4096) if was_running else 0.0)


# --- block_writes ---

COUNT = st.one_of(st.integers(0, 4095), st.just(FULL_OFF))
IMAGE = st.lists(st.one_of(st.none(), COUNT), min_size=16, max_size=16)


def apply(writes: list[tuple[int, bytes]], registers: bytearray) -> None:
    """The writes on a board with auto-increment: 64 bytes of LED registers from LED0_ON_L."""
    for register, data in writes:
        start = register - 0x06
        registers[start : start + len(data)] = data


def written_channels(writes: list[tuple[int, bytes]]) -> list[int]:
    return [(register - 0x06) // 4 + k for register, data in writes for k in range(len(data) // 4)]


@settings(max_examples=300, deadline=None)
@given(board=IMAGE, frame=IMAGE)
def test_block_writes_bring_the_board_to_the_frame(board: list[int | None], frame: list[int | None]) -> None:
    unknown = bytes([0xA5, 0x0A, 0x5A, 0x05])  # what a channel of unknown contents holds
    before = bytearray(b"".join(unknown if c is None else channel_bytes(c) for c in board))
    after = bytearray(before)
    writes = block_writes(board, frame)
    apply(writes, after)
    for channel in range(16):
        data = after[4 * channel : 4 * channel + 4]
        wanted = frame[channel]
        assert data == (before[4 * channel : 4 * channel + 4] if wanted is None else channel_bytes(wanted))


@settings(max_examples=300, deadline=None)
@given(board=IMAGE, frame=IMAGE)
def test_block_writes_write_only_changed_channels_in_few_blocks(
    board: list[int | None], frame: list[int | None]
) -> None:
    writes = block_writes(board, frame)
    changed = [c for c in range(16) if frame[c] is not None and frame[c] != board[c]]
    assert written_channels(writes) == changed  # each once, in order, never a None of the frame
    for register, data in writes:
        assert 0x06 <= register <= 0x42
        assert (register - 0x06) % 4 == 0
        assert 4 <= len(data) <= 32
        assert len(data) % 4 == 0
        assert register + len(data) - 1 <= 0x45
    runs: list[int] = []  # lengths of the runs of consecutive changed channels
    for k, channel in enumerate(changed):
        if k and changed[k - 1] == channel - 1:
            runs[-1] += 1
        else:
            runs.append(1)
    assert len(writes) == sum(math.ceil(run / 8) for run in runs)


@pytest.mark.parametrize(
    ("changed", "sizes"),
    [
        ([], []),
        ([5], [4]),
        (list(range(8)), [32]),
        (list(range(10)), [32, 8]),
        (list(range(16)), [32, 32]),
        ([0, 1, 3, 4, 5, 15], [8, 12, 4]),
    ],
)
def test_block_writes_split_runs_at_8_channels(changed: list[int], sizes: list[int]) -> None:
    board: list[int | None] = [100] * 16
    frame: list[int | None] = [200 if c in changed else 100 for c in range(16)]
    assert [len(data) for _, data in block_writes(board, frame)] == sizes


def test_block_writes_write_every_driven_channel_of_an_unknown_board() -> None:
    frame: list[int | None] = [None] * 16
    frame[3] = frame[4] = 307
    assert block_writes([None] * 16, frame) == [(0x06 + 12, channel_bytes(307) * 2)]
    assert block_writes([307] * 16, frame) == []
