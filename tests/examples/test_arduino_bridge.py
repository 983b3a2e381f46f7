"""The Arduino servo bridge (examples/arduino/): SSC-32 command lines in, PCA9685 writes out.

Host build: ``ssc32_bridge.h`` (the sketch's pure part) with tests/examples/arduino_host/driver.cpp,
compiled by g++ with warnings as errors and the address/undefined-behaviour sanitizers; the driver's
fake bus prints every I²C transaction, which is checked against the PCA9685 datasheet's numbers
computed here. Target build: the sketch for an Uno and a Nano with Debian's ``arduino-builder`` and
``arduino-core-avr``. Either toolchain missing skips its tests, unless ``URDAEMON_REQUIRE_ARDUINO=1``
(set by .ci/run, which installs both), where it fails.
"""

from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import pytest

from urdaemon.boards import pca9685, ssc32

ROOT = Path(__file__).resolve().parents[2]
SKETCH = ROOT / "examples" / "arduino" / "urdaemon_servo_bridge"
DRIVER = Path(__file__).resolve().parent / "arduino_host" / "driver.cpp"
REQUIRE_ENV = "URDAEMON_REQUIRE_ARDUINO"
"""Set to 1: a missing g++ or Arduino toolchain fails the tests instead of skipping them."""
ARDUINO_HARDWARE = Path("/usr/share/arduino/hardware")
"""Debian's arduino-core-avr: the platform ``arduino:avr`` (boards.txt, core, Wire) lives below it."""
BUILDER_SHARE = Path("/usr/share/arduino-builder")
"""Debian's arduino-builder: its platform.txt (the ctags recipe) is read as a hardware folder."""
GXX_FLAGS = (
    "-std=c++11",  # what the Arduino AVR platform compiles with (gnu++11)
    "-O1",
    "-g",
    "-fsanitize=address,undefined",
    "-fno-sanitize-recover=all",
    "-Wall",
    "-Wextra",
    "-Wpedantic",
    "-Wconversion",
    "-Wsign-conversion",
    "-Wshadow",
    "-Werror",
)
DEFAULT = {"BRIDGE_BOARDS": 2, "BRIDGE_OSCILLATOR_HZ": 25_000_000, "BRIDGE_PWM_HZ": 50}
"""The sketch's settings (urdaemon_servo_bridge.ino)."""


def _missing(reason: str) -> None:
    if os.environ.get(REQUIRE_ENV) == "1":
        pytest.fail(f"{reason} ({REQUIRE_ENV}=1)", pytrace=False)
    pytest.skip(reason)


def gxx_or_skip() -> str:
    """The host C++ compiler; skip (or fail under ``URDAEMON_REQUIRE_ARDUINO=1``) without one."""
    path = shutil.which("g++")
    if path is None:
        _missing("the bridge's host test needs g++ (Debian package: apt-get install g++)")
    assert path is not None
    return path


def arduino_builder_or_skip() -> str:
    """arduino-builder with the AVR core; skip (or fail under ``URDAEMON_REQUIRE_ARDUINO=1``), naming
    what is missing."""
    missing = []
    path = shutil.which("arduino-builder")
    if path is None or not (BUILDER_SHARE / "platform.txt").is_file():
        missing.append("arduino-builder")
    if not (ARDUINO_HARDWARE / "arduino" / "avr" / "libraries" / "Wire").is_dir():
        missing.append("arduino-core-avr")
    if missing:
        _missing(
            f"the sketch's build needs {' and '.join(missing)} "
            "(Debian: apt-get install --no-install-recommends arduino-builder arduino-core-avr)"
        )
    assert path is not None
    return path


# ---- The host build --------------------------------------------------------------------------------


def compile_driver(folder: Path, settings: dict[str, int]) -> subprocess.CompletedProcess[str]:
    """g++ on the driver and the bridge header with these BRIDGE_* settings, into ``folder``/driver."""
    defines = [f"-D{name}={value}" for name, value in settings.items()]
    command = [gxx_or_skip(), *GXX_FLAGS, f"-I{SKETCH}", *defines, str(DRIVER), "-o", str(folder / "driver")]
    return subprocess.run(command, capture_output=True, text=True, timeout=120, check=False)


@dataclass(frozen=True)
class Run:
    """What the driver printed for one input: the events after ``begin()`` split per input line."""

    begin: list[str]
    """Start-up writes and waits, up to and with the version line."""
    lines: list[list[str]]
    """Per input line (``\\r``): what the bridge did for it."""
    tail: list[str]
    """What it did after the last ``\\r`` (nothing: a group waits for its ``\\r``)."""
    dropped: int


def _parse(output: str) -> Run:
    events = output.splitlines()
    assert events, "the driver printed nothing"
    assert events[-1].startswith("Z dropped="), output[-500:]
    dropped = int(events.pop().removeprefix("Z dropped="))
    events = [f"wait>=500us({e[2:]})" if e.startswith("D ") and int(e[2:]) >= 500 else e for e in events]
    end = next(i for i, e in enumerate(events) if e.startswith("R ")) + 1
    lines: list[list[str]] = [[]]
    for event in events[end:]:
        if event == "E":
            lines.append([])
        else:
            lines[-1].append(event)
    return Run(events[:end], lines[:-1], lines[-1], dropped)


Bridge = Callable[..., Run]


@pytest.fixture(scope="module")
def bridge(tmp_path_factory: pytest.TempPathFactory) -> Bridge:
    """``bridge(input, absent=(), **settings)``: the driver built once per settings, run on ``input``."""
    built: dict[tuple[tuple[str, int], ...], Path] = {}

    def run(data: bytes | str, absent: Sequence[int] = (), **settings: int) -> Run:
        merged = {**DEFAULT, **settings}
        key = tuple(sorted(merged.items()))
        if key not in built:
            folder = tmp_path_factory.mktemp("bridge")
            compiled = compile_driver(folder, merged)
            assert compiled.returncode == 0, compiled.stderr
            built[key] = folder / "driver"
        args = [str(built[key])] + [arg for a in absent for arg in ("--absent", hex(a))]
        raw = data.encode("latin-1") if isinstance(data, str) else data
        env = {**os.environ, "ASAN_OPTIONS": "detect_leaks=0"}
        done = subprocess.run(args, input=raw, capture_output=True, timeout=60, check=False, env=env)
        assert done.returncode == 0, done.stderr.decode(errors="replace")
        return _parse(done.stdout.decode("ascii"))

    return run


def raw_writes(events: Sequence[str]) -> list[tuple[int, bytes]]:
    """The acknowledged writes as (address, raw bytes): what an smbus2-shaped bus's ``write`` would
    be given, register first (for replaying into a PCA9685 model)."""
    found = []
    for event in events:
        if event.startswith("W "):
            address, *data = event[2:].split()
            found.append((int(address, 16), bytes.fromhex("".join(d.removeprefix("0x") for d in data))))
    return found


def w(address: int, *data: int) -> str:
    """The driver's line for an acknowledged write of ``data`` (register first) to ``address``."""
    return f"W 0x{address:02x} 0x{data[0]:02x}" + "".join(f" {b:02x}" for b in data[1:])


def prescale(oscillator_hz: int = 25_000_000, pwm_hz: int = 50) -> int:
    """Datasheet equation 1: round(osc / (4096 f)) − 1."""
    return math.floor(Fraction(oscillator_hz, 4096 * pwm_hz) + Fraction(1, 2)) - 1


def exact_count(us: int, oscillator_hz: int = 25_000_000, pwm_hz: int = 50) -> Fraction:
    """us × f_real × 4096 / 1e6 with f_real = osc / (4096 (prescale + 1)), without rounding."""
    f_real = Fraction(oscillator_hz, 4096 * (prescale(oscillator_hz, pwm_hz) + 1))
    return us * f_real * 4096 / 1_000_000


def count(us: int, oscillator_hz: int = 25_000_000, pwm_hz: int = 50) -> int:
    """The OFF count of a pulse: the exact value rounded half up, within 0..4095."""
    return min(4095, math.floor(exact_count(us, oscillator_hz, pwm_hz) + Fraction(1, 2)))


def channel(ch: int, us: int, oscillator_hz: int = 25_000_000, pwm_hz: int = 50) -> str:
    """The write that sets channel ``ch`` (global: board ch // 16) to ``us`` (0: full off)."""
    off = (
        (0, 0x10)
        if us == 0
        else (count(us, oscillator_hz, pwm_hz) & 0xFF, count(us, oscillator_hz, pwm_hz) >> 8)
    )
    return w(0x40 + ch // 16, 0x06 + 4 * (ch % 16), 0, 0, *off)


def version(boards: int = 2, pwm_hz: int = 50, prescale_value: int = 121) -> str:
    """The driver's line for the bridge's version reply with these settings."""
    return f"R urdaemon-servo-bridge 1.0 boards={boards} pwm_hz={pwm_hz} prescale={prescale_value}"


def startup(address: int, prescale_value: int = 121) -> list[str]:
    """The datasheet's start-up: asleep, PRE_SCALE, MODE2 totem pole, awake with AI, wait, RESTART."""
    return [
        w(address, 0x00, 0x10),
        w(address, 0xFE, prescale_value),
        w(address, 0x01, 0x04),
        w(address, 0x00, 0x20),
        "wait>=500us(500)",
        w(address, 0x00, 0xA0),
    ]


# ---- Start-up and counts -----------------------------------------------------------------------------


def test_startup_follows_the_datasheet_on_both_boards(bridge: Bridge) -> None:
    run = bridge("")
    assert prescale() == 121
    assert run.begin == [
        *startup(0x40),
        *startup(0x41),
        version(),
    ]
    # The same writes the daemon's own I2C path makes (urdaemon/boards/pca9685.py).
    until_wake, after = pca9685.startup_writes(pca9685.prescale_for(50.0))
    daemon = [w(0x40, *write) for write in until_wake] + ["wait>=500us(500)"] + [w(0x40, *after[0])]
    assert run.begin[:6] == daemon
    assert run.lines == []
    assert run.tail == []
    assert run.dropped == 0


@pytest.mark.parametrize(("oscillator_hz", "pwm_hz"), [(25_000_000, 50), (26_075_000, 50), (24_700_000, 60)])
def test_every_pulse_gets_the_datasheet_count(bridge: Bridge, oscillator_hz: int, pwm_hz: int) -> None:
    pulses = range(500, 2501)
    run = bridge(
        "".join(f"#3P{us}\r" for us in pulses), BRIDGE_OSCILLATOR_HZ=oscillator_hz, BRIDGE_PWM_HZ=pwm_hz
    )
    assert run.begin[-1] == version(pwm_hz=pwm_hz, prescale_value=prescale(oscillator_hz, pwm_hz))
    assert run.begin[1] == w(0x40, 0xFE, prescale(oscillator_hz, pwm_hz))
    assert run.lines == [[channel(3, us, oscillator_hz, pwm_hz)] for us in pulses]
    assert run.dropped == 0


def test_counts_agree_with_the_daemons_i2c_path(bridge: Bridge) -> None:
    """The bridge and pca9685.count_for give every whole-µs pulse the same count, exact halves
    (915 µs is 187.5 counts) rounded up by both."""
    pulses = range(500, 2501)
    run = bridge("".join(f"#0P{us}\r" for us in pulses))
    by_bridge = {
        us: int(lines[0].split()[-2], 16) + 256 * int(lines[0].split()[-1], 16)
        for us, lines in zip(pulses, run.lines, strict=True)
    }
    daemon = {us: pca9685.count_for(us, pca9685.prescale_for(50.0)) for us in pulses}
    assert by_bridge == daemon
    halves = {us for us in pulses if exact_count(us).denominator == 2}
    assert 915 in halves
    assert all(daemon[us] == math.ceil(exact_count(us)) for us in halves)


def test_counts_above_the_period_are_clamped_to_4095(bridge: Bridge) -> None:
    run = bridge("#0P2500\r#1P900\r", BRIDGE_PWM_HZ=1000)
    assert prescale(pwm_hz=1000) == 5
    assert count(2500, pwm_hz=1000) == 4095
    assert run.lines == [[w(0x40, 0x06, 0, 0, 0xFF, 0x0F)], [channel(1, 900, pwm_hz=1000)]]


# ---- Command groups --------------------------------------------------------------------------------


def test_p0_turns_a_channel_full_off(bridge: Bridge) -> None:
    run = bridge("#5P1500\r#5P0\r#21P000\r")
    assert run.lines == [[channel(5, 1500)], [w(0x40, 0x1A, 0, 0, 0, 0x10)], [w(0x41, 0x1A, 0, 0, 0, 0x10)]]


def test_channels_16_to_31_are_the_second_board(bridge: Bridge) -> None:
    pulses = {ch: 600 + 50 * ch for ch in range(32)}
    run = bridge("".join(f"#{ch}P{us}" for ch, us in reversed(pulses.items())) + "\r")
    assert run.lines == [[channel(ch, us) for ch, us in pulses.items()]]  # board by board, in channel order
    writes = raw_writes(run.lines[0])
    assert [a for a, _ in writes] == [0x40] * 16 + [0x41] * 16
    assert all(len(data) == 5 for _, data in writes)  # one transaction per channel, well inside Wire's 32
    assert writes[15] == (0x40, bytes((0x42, 0, 0, count(1350) & 0xFF, count(1350) >> 8)))


def test_pulses_outside_500_to_2500_are_clamped_like_an_ssc32(bridge: Bridge) -> None:
    given = [1, 250, 499, 500, 2500, 2501, 65535, 4_000_000_000]
    run = bridge("".join(f"#7P{us}\r" for us in given))
    made = [500, 500, 500, 500, 2500, 2500, 2500, 2500]
    assert run.lines == [[channel(7, us)] for us in made]


MALFORMED = [
    "#0P1500#1PX",  # a letter for a number
    "#0P1500#32P1500",  # no channel 32 with two boards
    "#0P1500#",  # a channel without its number
    "#0P1500#1",  # without its pulse
    "#0P",
    "#P1500",
    "#0P1500T",  # T without its time
    "#0P1500T20#1P1600",  # anything after T
    "#0P1500T20T20",
    "0P1500",  # no '#'
    "#0P1500S100",  # per-servo speed: not taken
    "#0P15.5",
    "#0P-1",
    "#0P1500\x00",
    "#0P1500\xe9",
    "VERX",
    "Q",
]


def test_a_malformed_group_is_dropped_whole(bridge: Bridge) -> None:
    run = bridge("".join(f"{line}\r" for line in MALFORMED) + "#0P1500\r")
    assert run.lines == [[] for _ in MALFORMED] + [[channel(0, 1500)]]
    assert run.dropped == len(MALFORMED)


def test_a_group_is_applied_only_at_its_carriage_return(bridge: Bridge) -> None:
    waiting = bridge("#0P1500#1P1600")
    assert waiting.lines == []
    assert waiting.tail == []  # nothing at the end of the input either
    assert waiting.dropped == 0
    lf = bridge("#0P1500\n#1P1600\n\r\n")
    assert lf.lines == [[channel(0, 1500), channel(1, 1600)]]  # one group: a line feed ends nothing
    assert lf.tail == []


def test_spaces_tabs_line_feeds_and_case_do_not_matter(bridge: Bridge) -> None:
    run = bridge("\n# 0 p 1500\t#1P1600 t 20\r#2p0\r  \r")
    assert run.lines == [[channel(0, 1500), channel(1, 1600)], [channel(2, 0)], []]
    assert run.dropped == 0


def test_move_time_is_read_and_ignored(bridge: Bridge) -> None:
    run = bridge("#4P900T1000\r#4P900\r#4P1100T65535\r#4P1200T999999\r")
    assert run.lines == [[channel(4, 900)], [channel(4, 900)], [channel(4, 1100)], [channel(4, 1200)]]


def test_an_overlong_line_is_dropped_and_the_next_one_applied(bridge: Bridge) -> None:
    longest = "#0P1500" * 37 + "T1000"  # 264 characters kept: 8 per channel and 8 more, 32 channels
    assert len(longest) == 32 * 8 + 8
    run = bridge(f"{longest}\r{longest}0\r{' '.join(longest)}\r#1P1600\r")
    assert run.lines == [[channel(0, 1500)], [], [channel(0, 1500)], [channel(1, 1600)]]
    assert run.dropped == 1


def test_ver_is_answered_with_a_version_line(bridge: Bridge) -> None:
    run = bridge("VER\rv e r\r")
    assert run.lines == [[version()], [version()]]


def test_the_daemons_own_lines_drive_the_board(bridge: Bridge) -> None:
    """Lines made by urdaemon/boards/ssc32.py, as the serial output sends them."""
    sent = [
        ssc32.group_line([(0, 1500), (17, 900), (3, 2400)]),
        ssc32.group_line([(0, 1510)], move_time_ms=20),
        ssc32.off_line([0, 3, 17]),
    ]
    run = bridge(b"".join(sent))
    assert run.lines == [
        [channel(0, 1500), channel(3, 2400), channel(17, 900)],
        [channel(0, 1510)],
        [channel(0, 0), channel(3, 0), channel(17, 0)],
    ]


# ---- Boards that do not answer ---------------------------------------------------------------------


def test_a_board_absent_at_start_is_started_when_it_answers(bridge: Bridge) -> None:
    run = bridge("#16P1500#17P1600\r#2P700\r@present 0x41\n#18P1700\r", absent=[0x41])
    assert run.begin[6:] == ["N 0x41 0x00 10", version()]
    assert run.lines[0] == ["N 0x41 0x00 10"]  # tried again, nothing else sent to it
    assert run.lines[1] == [channel(2, 700)]  # the other board is not held up
    assert run.lines[2] == [*startup(0x41), channel(16, 1500), channel(17, 1600), channel(18, 1700)]


def test_a_board_that_stopped_answering_is_started_again_with_all_its_pulses(bridge: Bridge) -> None:
    run = bridge("#0P1500#20P900\r@absent 0x40\n#1P1600\r#3P0\r@present 0x40\n#2P1700\r#4P800\r")
    assert run.lines[0] == [channel(0, 1500), channel(20, 900)]
    assert run.lines[1] == ["N" + channel(1, 1600)[1:]]
    assert run.lines[2] == ["N 0x40 0x00 10"]
    assert run.lines[3] == [
        *startup(0x40),
        channel(0, 1500),
        channel(1, 1600),
        channel(2, 1700),
        channel(3, 0),
    ]
    assert run.lines[4] == [channel(4, 800)]


# ---- Other settings ----------------------------------------------------------------------------------


def test_one_board_has_channels_0_to_15_only(bridge: Bridge) -> None:
    run = bridge("#16P1500\r#15P1500\r", BRIDGE_BOARDS=1)
    assert run.begin == [*startup(0x40), version(boards=1)]
    assert run.lines == [[], [channel(15, 1500)]]
    assert run.dropped == 1


def test_four_boards_reach_channel_63_at_0x43(bridge: Bridge) -> None:
    run = bridge("#63P1500#32P1000\r#64P1500\r", BRIDGE_BOARDS=4)
    assert run.begin[:-1] == [*startup(0x40), *startup(0x41), *startup(0x42), *startup(0x43)]
    assert run.lines == [[w(0x42, 0x06, 0, 0, count(1000) & 0xFF, count(1000) >> 8), channel(63, 1500)], []]
    assert channel(63, 1500).startswith("W 0x43 0x42 ")


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"BRIDGE_PWM_HZ": 10}, "prescale outside 3..255"),
        ({"BRIDGE_PWM_HZ": 2000}, "prescale outside 3..255"),
        ({"BRIDGE_OSCILLATOR_HZ": 25_000_001}, "whole kHz"),
        ({"BRIDGE_BOARDS": 5}, "BRIDGE_BOARDS is 1..4"),
    ],
)
def test_settings_the_chip_cannot_take_do_not_compile(
    tmp_path: Path, settings: dict[str, int], message: str
) -> None:
    done = compile_driver(tmp_path, {**DEFAULT, **settings})
    assert done.returncode != 0
    assert message in done.stderr
    assert compile_driver(tmp_path, DEFAULT).returncode == 0  # the same build with the sketch's settings


# ---- The sketch for a real board -------------------------------------------------------------------


def builder_command(builder: str, fqbn: str, build_path: Path, ino: Path) -> list[str]:
    """arduino-builder for Debian's packages. ``DECIMAL_DIG``: arduino-core-avr 1.8.7's WString.cpp
    needs it, and Debian's avr-gcc 5.4 defines it for C only (upstream builds with avr-gcc 7)."""
    return [
        builder,
        "-hardware", str(ARDUINO_HARDWARE),
        "-hardware", str(BUILDER_SHARE),
        "-tools", str(BUILDER_SHARE),
        "-fqbn", fqbn,
        "-prefs", "compiler.cpp.extra_flags=-DDECIMAL_DIG=__DECIMAL_DIG__",
        "-warnings", "all",
        "-build-path", str(build_path),
        str(ino),
    ]  # fmt: skip


def build_sketch(folder: Path, fqbn: str, old: str = "", new: str = "") -> tuple[int, str]:
    """arduino-builder on a copy of the sketch in ``folder`` with ``old`` replaced by ``new`` in the
    .ino: its exit status and everything it printed."""
    builder = arduino_builder_or_skip()
    ino = folder / "urdaemon_servo_bridge" / "urdaemon_servo_bridge.ino"
    shutil.copytree(SKETCH, ino.parent)
    text = ino.read_text(encoding="utf-8")
    assert old in text
    ino.write_text(text.replace(old, new), encoding="utf-8")
    (folder / "build").mkdir()
    command = builder_command(builder, fqbn, folder / "build", ino)
    done = subprocess.run(command, capture_output=True, text=True, timeout=300, check=False)
    return done.returncode, done.stdout + done.stderr


@pytest.mark.parametrize(
    ("fqbn", "boards"),
    [("arduino:avr:uno", 2), ("arduino:avr:nano:cpu=atmega328", 2), ("arduino:avr:uno", 4)],
)
def test_the_sketch_builds_for_a_328p_board_and_fits(tmp_path: Path, fqbn: str, boards: int) -> None:
    status, report = build_sketch(
        tmp_path, fqbn, "#define BRIDGE_BOARDS 2 ", f"#define BRIDGE_BOARDS {boards} "
    )
    assert status == 0, report
    flash = re.search(r"Sketch uses (\d+) bytes .* Maximum is (\d+) bytes", report)
    ram = re.search(r"Global variables use (\d+) bytes .* Maximum is (\d+) bytes", report)
    assert flash is not None, report
    assert ram is not None, report
    assert int(flash[1]) <= int(flash[2]) <= 32 * 1024  # the ATmega328P's 32 KB, less the bootloader
    assert int(ram[1]) + 512 <= int(ram[2]) == 2048  # room left for the stack
    assert (tmp_path / "build" / "urdaemon_servo_bridge.ino.hex").stat().st_size > 0
    ours = [line for line in report.splitlines() if "warning" in line and str(tmp_path) in line]
    assert ours == []


def test_the_build_reports_warnings_in_the_sketch(tmp_path: Path) -> None:
    """A guard for the warnings check above: a sketch with an unused variable is reported by name."""
    status, report = build_sketch(
        tmp_path, "arduino:avr:uno", "void loop() {", "void loop() {\n  int unused;"
    )
    assert status == 0, report
    assert re.search(r"urdaemon_servo_bridge\.ino:\d+:\d+: warning: unused variable", report), report


def test_five_boards_do_not_build(tmp_path: Path) -> None:
    status, report = build_sketch(
        tmp_path, "arduino:avr:uno", "#define BRIDGE_BOARDS 2 ", "#define BRIDGE_BOARDS 5 "
    )
    assert status != 0
    assert "BRIDGE_BOARDS is 1..4" in report


# ---- The rule for a missing toolchain ----------------------------------------------------------------


def test_without_a_toolchain_the_tests_skip_naming_the_packages(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(shutil, "which", lambda name: None)
    monkeypatch.delenv(REQUIRE_ENV, raising=False)
    with pytest.raises(pytest.skip.Exception, match=r"needs g\+\+ \(Debian package: apt-get install g\+\+\)"):
        gxx_or_skip()
    with pytest.raises(
        pytest.skip.Exception, match=r"needs arduino-builder .*arduino-builder arduino-core-avr"
    ):
        arduino_builder_or_skip()


def test_without_a_toolchain_they_fail_when_it_is_required(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(shutil, "which", lambda name: None)
    monkeypatch.setenv(REQUIRE_ENV, "1")
    with pytest.raises(pytest.fail.Exception, match=r"g\+\+.*URDAEMON_REQUIRE_ARDUINO=1"):
        gxx_or_skip()
    with pytest.raises(pytest.fail.Exception, match=r"arduino-builder.*URDAEMON_REQUIRE_ARDUINO=1"):
        arduino_builder_or_skip()
