"""What a servo arm's outputs cost: the robot's cycle per output configuration, what the writer
threads put on their devices, and one frame's write on each link. In process, on counting fakes of
an I²C bus and a serial port (no board needed).

    python benchmarks/servo_outputs.py [--seconds S] [--runs R]

(a) **The cycle.** The arm of configs/servo_arm.yaml (4 joints, channels 0–3) runs ``ServoBackend.run``
at 50 Hz (the shipped rate) and at 500 Hz (the most ``rate_hz`` takes) for S seconds (default 4) per
case, following a sinusoid on every joint as a controller would command it; only ``step()`` is
timed (the backend is subclassed, ``step`` wraps the real one). Cases: no output at all (the
baseline: nothing published, no device), ``zenoh`` (the ``servo_command`` message built and handed to
a no-op publisher), ``i2c`` (a ``Pca9685Link`` over a bus whose writes only count), ``serial`` (an
``Ssc32Link`` over a port that only counts bytes), and all three. CPU-s/s is the whole process
(``time.process_time``: the loop thread, the writer threads) over the run, divided by the seconds.

(b) **The writers.** From the same runs: frames written and bus transfers (I²C block writes, serial
lines) per second, frames superseded, and what the counted bytes would occupy on a real bus: an I²C
transfer takes (2 + data bytes) × 9 + 2 bit times (address, register, data, each acknowledged; start
and stop), a serial byte 10 bit times (8N1).

(c) **One frame's write.** ``Pca9685Link.write`` and ``Ssc32Link.write`` for 4, 16 and 32 channels
(32: two chained PCA9685 boards), every channel changed from the frame before, and unchanged (nothing
to write): µs per call, the minimum over R runs (default 5) of 20 000 calls.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import math
import os
import platform
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from urdaemon.backends.servo import ServoBackend
from urdaemon.backends.servo.i2c_link import Pca9685Link
from urdaemon.backends.servo.link import BoardLink
from urdaemon.backends.servo.serial_link import Ssc32Link
from urdaemon.cell import load_cell
from urdaemon.cell.servo import I2cOutput, SerialOutput, ServoOptions
from urdaemon.daemon import describe_cell
from urdaemon.model import CommandMode

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "servo_arm.yaml"
RATES_HZ = (50.0, 500.0)
AMPLITUDE_RAD = 0.8
PERIOD_S = 4.0
"""The sinusoid every joint follows (phase-shifted per joint): up to 1.26 rad/s."""
WRITE_CALLS = 20_000
I2C_BIT_RATES = (100_000, 400_000)
"""The Raspberry Pi's default I²C clock, and fast mode (``dtparam=i2c_arm_baudrate=400000``)."""
SERIAL_BAUD = 115_200


# ---- counting fakes of the devices ------------------------------------------------------------------


@dataclass
class Tally:
    """What a fake device was asked to carry."""

    transfers: int = 0
    data_bytes: int = 0
    bus_bits: int = 0
    """I²C: bit times the transfers would take on the wire."""


class CountingBus:
    """An smbus2-shaped bus whose writes only count."""

    def __init__(self, tally: Tally) -> None:
        self.tally = tally

    def write_byte_data(self, i2c_addr: int, register: int, value: int) -> None:
        """Count one register write (start-up, off)."""
        self._count(1)

    def write_i2c_block_data(self, i2c_addr: int, register: int, data: Sequence[int]) -> None:
        """Count one block write."""
        self._count(len(data))

    def read_byte_data(self, i2c_addr: int, register: int) -> int:
        """The idle probe's MODE1 read: a board awake with auto-increment, as started."""
        self._count(1)
        return 0x20

    def _count(self, size: int) -> None:
        tally = self.tally
        tally.transfers += 1
        tally.data_bytes += size
        tally.bus_bits += (2 + size) * 9 + 2

    def close(self) -> None:
        """Nothing to release."""


class CountingPort:
    """A pyserial-shaped port that only counts what it is given."""

    def __init__(self, tally: Tally) -> None:
        self.tally = tally

    def write(self, data: bytes) -> int:
        """Count one line."""
        self.tally.transfers += 1
        self.tally.data_bytes += len(data)
        return len(data)

    def read(self, size: int = 1) -> bytes:
        """A board that says nothing (the link drives it once its wait for an answer has passed)."""
        return b""

    def close(self) -> None:
        """Nothing to release."""


def i2c_link(options: ServoOptions, output: I2cOutput, tally: Tally) -> Pca9685Link:
    """A PCA9685 link on a counting bus (the oscillator's settling wait skipped)."""
    channels = [j.channel for j in options.joints]
    return Pca9685Link(
        output,
        options.pwm_frequency_hz,
        channels,
        open_bus=lambda _bus: CountingBus(tally),
        sleep=lambda _s: None,
    )


def serial_link(options: ServoOptions, output: SerialOutput, tally: Tally) -> Ssc32Link:
    """An SSC-32 link on a counting port."""
    channels = [j.channel for j in options.joints]
    return Ssc32Link(output, channels, open_port=lambda _output: CountingPort(tally), ready_wait_s=0.0)


# ---- (a) and (b): the cycle and the writers -------------------------------------------------------------


class TimedServo(ServoBackend):
    """The servo backend with each ``step`` timed (ns), the rest unchanged."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.step_ns: list[int] = []

    def step(self) -> None:
        """The real step, timed."""
        start = time.perf_counter_ns()
        super().step()
        self.step_ns.append(time.perf_counter_ns() - start)


@dataclass
class Case:
    """One output configuration: the cell file's outputs, and whether a publisher is given."""

    label: str
    outputs: list[dict[str, Any]]
    publish: bool


CASES = (
    Case("none (baseline)", [{"kind": "zenoh"}], publish=False),
    Case("zenoh", [{"kind": "zenoh"}], publish=True),
    Case("i2c", [{"kind": "i2c", "address": 0x40}], publish=False),
    Case("serial", [{"kind": "serial", "port": "/dev/ttyBENCH"}], publish=False),
    Case(
        "zenoh + i2c + serial",
        [{"kind": "zenoh"}, {"kind": "i2c", "address": 0x40}, {"kind": "serial", "port": "/dev/ttyBENCH"}],
        publish=True,
    ),
)


@dataclass
class CycleRow:
    """One case at one rate: the step's cost, and each device output's report and tally."""

    label: str
    rate_hz: float
    cycles: int
    seconds: float
    median_us: float
    p99_us: float
    cpu: float
    outputs: list[tuple[dict[str, Any], Tally]] = field(default_factory=list)


def sinusoid(dof: int, rate_hz: float) -> Callable[[int], list[float]]:
    """Joint positions at cycle k: every joint on a sinusoid, phase-shifted per joint."""

    def at(k: int) -> list[float]:
        t = k / rate_hz
        return [AMPLITUDE_RAD * math.sin(2.0 * math.pi * t / PERIOD_S + 0.7 * j) for j in range(dof)]

    return at


async def run_case(
    case: Case, base: dict[str, Any], names: Sequence[str], prefix: str, rate_hz: float, seconds: float
) -> CycleRow:
    """Run the backend for ``seconds`` at ``rate_hz`` with ``case``'s outputs; its figures."""
    options = ServoOptions.model_validate({**base, "outputs": case.outputs, "rate_hz": rate_hz})
    links: list[BoardLink] = []
    tallies: list[Tally] = []
    for output in options.outputs:
        tally = Tally()
        if isinstance(output, I2cOutput):
            links.append(i2c_link(options, output, tally))
        elif isinstance(output, SerialOutput):
            links.append(serial_link(options, output, tally))
        else:
            continue
        tallies.append(tally)
    publish: Callable[[bytes], None] | None = (lambda _payload: None) if case.publish else None
    backend = TimedServo("arm", names, prefix, options, publish=publish, links=links)
    cycles = max(1, round(seconds * rate_hz))
    motion = sinusoid(len(names), rate_hz)
    command = backend.command
    command.mode = CommandMode.POSITION
    done = asyncio.Event()

    def on_cycle() -> None:  # the controller's place: the next cycle's command
        k = len(backend.step_ns)
        command.positions[:] = motion(k)
        if k >= cycles:
            done.set()

    cpu0, wall0 = time.process_time(), time.monotonic()
    task = asyncio.create_task(backend.run(on_cycle))
    await asyncio.wait_for(done.wait(), timeout=seconds * 3 + 5)
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task
    cpu, wall = time.process_time() - cpu0, time.monotonic() - wall0
    samples = sorted(ns / 1000.0 for ns in backend.step_ns)
    reports = backend.output_reports() or []
    return CycleRow(
        label=case.label,
        rate_hz=rate_hz,
        cycles=len(samples),
        seconds=wall,
        median_us=statistics.median(samples),
        p99_us=samples[int(0.99 * (len(samples) - 1))],
        cpu=cpu / wall,
        outputs=list(zip(reports, tallies, strict=True)),
    )


def print_cycles(rows: Sequence[CycleRow]) -> None:
    """Table (a): the step's cost per case and rate."""
    print("\n(a) ServoBackend.step() per cycle, 4 joints moving")
    print(f"{'outputs':<22} {'rate Hz':>7} {'cycles':>7} {'median µs':>10} {'p99 µs':>8} {'CPU-s/s':>8}")
    for r in rows:
        cost = f"{r.median_us:>10.1f} {r.p99_us:>8.1f} {r.cpu:>8.4f}"
        print(f"{r.label:<22} {r.rate_hz:>7.0f} {r.cycles:>7} {cost}")


def print_writers(rows: Sequence[CycleRow]) -> None:
    """Table (b): what each device output's writer did, per second, and the bus time it would take."""
    print("\n(b) the writer threads (device outputs), per second of a moving arm")
    print(
        f"{'outputs':<22} {'rate Hz':>7} {'output':<28} {'frames/s':>9} {'transfers/s':>12} "
        f"{'superseded':>10} {'bytes/s':>8}  bus busy"
    )
    for r in rows:
        for report, tally in r.outputs:
            label = str(report["output"])
            if label.startswith("i2c"):
                busy = ", ".join(
                    f"{tally.bus_bits / r.seconds / rate:.1%} at {rate // 1000} kHz" for rate in I2C_BIT_RATES
                )
            else:
                busy = f"{tally.data_bytes * 10 / r.seconds / SERIAL_BAUD:.1%} at {SERIAL_BAUD} baud"
            print(
                f"{r.label:<22} {r.rate_hz:>7.0f} {label:<28} {int(report['frames']) / r.seconds:>9.1f} "
                f"{int(report['transfers']) / r.seconds:>12.1f} {report['superseded']:>10} "
                f"{tally.data_bytes / r.seconds:>8.0f}  {busy}"
            )


# ---- (c): one frame's write ---------------------------------------------------------------------------


def time_writes(link: BoardLink, frames: Sequence[Sequence[float]], runs: int) -> float:
    """µs per ``write``, cycling through ``frames``: the minimum over ``runs`` runs."""
    link.open()
    link.write(frames[0])
    best = math.inf
    count = len(frames)
    write = link.write
    for _ in range(runs):
        start = time.perf_counter_ns()
        for k in range(WRITE_CALLS):
            write(frames[k % count])
        best = min(best, (time.perf_counter_ns() - start) / WRITE_CALLS / 1000.0)
    link.close()
    return best


def write_costs(runs: int) -> list[tuple[str, int, float, float]]:
    """(link, channels, µs per changed frame, µs per unchanged frame) for 4, 16 and 32 channels."""
    rows = []
    for width in (4, 16, 32):
        joints = [{"name": f"j{c}", "channel": c} for c in range(width)]
        options = ServoOptions.model_validate({"joints": joints})
        a = [1000.0 + 10.0 * c for c in range(width)]
        b = [p + 250.0 for p in a]  # every channel moves by 250 µs (~51 counts at 50 Hz)
        i2c = I2cOutput(kind="i2c", address=(0x40,) if width <= 16 else (0x40, 0x41))
        port = SerialOutput(kind="serial", port="/dev/ttyBENCH")
        changed = time_writes(i2c_link(options, i2c, Tally()), [a, b], runs)
        unchanged = time_writes(i2c_link(options, i2c, Tally()), [a], runs)
        rows.append(("Pca9685Link.write", width, changed, unchanged))
        changed = time_writes(serial_link(options, port, Tally()), [a, b], runs)
        unchanged = time_writes(serial_link(options, port, Tally()), [a], runs)
        rows.append(("Ssc32Link.write", width, changed, unchanged))
    return rows


def print_writes(rows: Sequence[tuple[str, int, float, float]]) -> None:
    """Table (c)."""
    print(f"\n(c) one frame's write, min of runs of {WRITE_CALLS} calls")
    print(f"{'link':<20} {'channels':>8} {'changed µs':>11} {'unchanged µs':>13}")
    for label, width, changed, unchanged in rows:
        print(f"{label:<20} {width:>8} {changed:>11.2f} {unchanged:>13.2f}")


async def cycles(seconds: float) -> list[CycleRow]:
    """Every case at every rate, one after the other."""
    cell = load_cell(CONFIG)
    robot = cell.robot("arm")
    assert robot.servo is not None
    names = describe_cell(cell).limits["arm"].names
    base = robot.servo.model_dump(exclude={"outputs", "rate_hz"})
    rows = []
    for rate in RATES_HZ:
        for case in CASES:
            rows.append(await run_case(case, base, names, robot.prefix, rate, seconds))
    return rows


def main() -> None:
    """Run (a), (b) and (c) and print their tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--seconds", type=float, default=4.0, help="seconds per case and rate (a, b)")
    parser.add_argument("--runs", type=int, default=5, help="runs of each write measurement (c)")
    args = parser.parse_args()
    print(
        f"machine: {platform.machine()} {platform.processor()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}"
    )
    rows = asyncio.run(cycles(args.seconds))
    print_cycles(rows)
    print_writers(rows)
    print_writes(write_costs(args.runs))


if __name__ == "__main__":
    main()
