"""The ``servo`` section of a robot in the cell file: a hobby-servo arm's joints, how each maps to a
pulse, and the outputs that carry the pulses to the servos (docs/servo.md).

Channels are numbered across the boards of an output: on an ``i2c`` output listing addresses
[0x40, 0x41], channels 0–15 are the first board's and 16–31 the second's; an SSC-32 board has 0–31.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from urdaemon.boards import pca9685, ssc32
from urdaemon.cell.schema_types import MIN_CYCLE_RATE_HZ, Finite, Frozen

__all__ = [
    "I2C_ADDRESS_RANGE",
    "MAX_CHANNEL",
    "I2cOutput",
    "SerialOutput",
    "ServoJoint",
    "ServoOptions",
    "ServoOutput",
    "ZenohOutput",
]

I2C_ADDRESS_RANGE = (0x40, 0x7F)
"""The addresses a PCA9685 can be strapped to (A5..A0 behind a fixed high bit)."""
MAX_CHANNEL = pca9685.CHANNELS * (I2C_ADDRESS_RANGE[1] - I2C_ADDRESS_RANGE[0] + 1) - 1
"""The highest channel number: the last channel of a chain of every board address there is."""


class ServoJoint(Frozen):
    """One joint of a servo arm mapped to an output channel."""

    name: Annotated[str, Field(pattern=r"^[A-Za-z0-9_]+$")]
    """Joint name in the robot's description, without the robot prefix."""
    channel: Annotated[int, Field(ge=0, le=MAX_CHANNEL)]
    """The output channel: 0–15 on the first PCA9685 of a chain, 16–31 on the second, …"""
    pulse_min_us: Annotated[float, Field(gt=0, lt=20000, allow_inf_nan=False)] = 500.0
    pulse_max_us: Annotated[float, Field(gt=0, lt=20000, allow_inf_nan=False)] = 2500.0
    angle_min: Finite = -math.pi / 2
    """Joint angle (rad) that maps to ``pulse_min_us`` (before offset and direction)."""
    angle_max: Finite = math.pi / 2
    """Joint angle (rad) that maps to ``pulse_max_us``."""
    offset: Finite = 0.0
    """Added to the joint angle before mapping (rad): the servo's zero vs the joint's zero."""
    direction: Literal[1, -1] = 1

    @model_validator(mode="after")
    def _ranges(self) -> ServoJoint:
        if self.pulse_min_us >= self.pulse_max_us:
            raise ValueError(
                f"pulse_min_us {self.pulse_min_us} must be below pulse_max_us {self.pulse_max_us}"
            )
        if self.angle_min >= self.angle_max:
            raise ValueError(f"angle_min {self.angle_min} must be below angle_max {self.angle_max}")
        return self


class ZenohOutput(Frozen):
    """Publish each cycle's pulses and PCA9685 counts on ``<cell>/<robot>/servo_command``."""

    kind: Literal["zenoh"]

    @property
    def label(self) -> str:
        """How messages name this output."""
        return "zenoh servo_command"


class I2cOutput(Frozen):
    """PCA9685 boards on a Linux I²C bus (``/dev/i2c-<bus>``), chained by address."""

    kind: Literal["i2c"]
    bus: Annotated[int, Field(ge=0, le=255)] = 1
    """The bus number: 1 is the 40-pin header's SDA/SCL on a Raspberry Pi."""
    address: tuple[int, ...] = (0x40,)
    """The board's address, or the chain's as a list in channel order (channels 0–15 on the first, …)."""
    oscillator_hz: Annotated[float, Field(ge=20e6, le=30e6, allow_inf_nan=False)] = (
        pca9685.DEFAULT_OSCILLATOR_HZ
    )
    """The board's oscillator as measured (docs/servo.md, calibration); 25 MHz nominal."""

    @field_validator("address", mode="before")
    @classmethod
    def _one_or_many(cls, value: object) -> object:
        return (value,) if isinstance(value, int) and not isinstance(value, bool) else value

    @field_validator("address")
    @classmethod
    def _on_the_chip(cls, value: tuple[int, ...]) -> tuple[int, ...]:
        low, high = I2C_ADDRESS_RANGE
        for address in value:
            if not low <= address <= high:
                raise ValueError(
                    f"{address:#04x} ({address}) is not a PCA9685 address: the A0–A5 jumpers give "
                    f"{low:#04x}–{high:#04x}"
                )
        return value

    @property
    def device(self) -> str:
        """The bus's device file."""
        return f"/dev/i2c-{self.bus}"

    @property
    def label(self) -> str:
        """How messages name this output."""
        return f"i2c bus {self.bus} ({', '.join(f'0x{a:02x}' for a in self.address)})"

    @model_validator(mode="after")
    def _boards(self) -> I2cOutput:
        if not self.address:
            raise ValueError("'address' lists no board")
        twice = sorted({a for a in self.address if self.address.count(a) > 1})
        if twice:
            raise ValueError(f"address {', '.join(f'0x{a:02x}' for a in twice)} is listed twice")
        return self


class SerialOutput(Frozen):
    """A serial servo controller that takes SSC-32 command lines (an SSC-32, the Arduino bridge)."""

    kind: Literal["serial"]
    port: Annotated[str, Field(min_length=1)]
    """The serial device, e.g. ``/dev/ttyUSB0`` or a ``/dev/serial/by-id/…`` name."""
    baud: Annotated[int, Field(ge=300, le=4_000_000)] = 115200
    protocol: Literal["ssc32"] = "ssc32"
    move_time_ms: (
        Annotated[int, Field(ge=ssc32.MOVE_TIME_RANGE_MS[0], le=ssc32.MOVE_TIME_RANGE_MS[1])] | None
    ) = None
    """``T`` of each command group: the board spreads each step over this time (none: at once)."""

    @property
    def label(self) -> str:
        """How messages name this output."""
        return f"serial {self.port}"


ServoOutput = Annotated[ZenohOutput | I2cOutput | SerialOutput, Field(discriminator="kind")]


class ServoOptions(Frozen):
    """Options of the ``servo`` backend (hobby servos, no feedback: the state follows the command)."""

    pwm_frequency_hz: Annotated[
        float, Field(ge=pca9685.FREQUENCY_RANGE_HZ[0], le=pca9685.FREQUENCY_RANGE_HZ[1])
    ] = 50.0
    """PCA9685 output frequency; the datasheet's range is 24..1526 Hz."""
    rate_hz: Annotated[float, Field(ge=MIN_CYCLE_RATE_HZ, le=500)] = 50.0
    """Control cycle rate, 10..500 Hz: how often commands are computed and sent."""
    joints: tuple[ServoJoint, ...]
    initial_positions: dict[str, Finite] | None = None
    outputs: tuple[ServoOutput, ...] = (ZenohOutput(kind="zenoh"),)
    """Where the pulses go; several at once are allowed (a board and the Zenoh key, say)."""
    safe_state: Literal["hold", "off"] = "hold"
    """What the servos get when the daemon stops driving them: the last pulse (``hold``) or none
    (``off``, the servos go limp)."""

    @property
    def publishes(self) -> bool:
        """True when the pulses are also published on ``<cell>/<robot>/servo_command``."""
        return any(isinstance(o, ZenohOutput) for o in self.outputs)

    @model_validator(mode="after")
    def _consistent(self) -> ServoOptions:
        if not self.joints:
            raise ValueError("'joints' must list at least one servo joint")
        if not self.outputs:
            raise ValueError("'outputs' lists nothing; the default is [{kind: zenoh}]")
        names = [j.name for j in self.joints]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"duplicate joint name: {', '.join(twice)}")
        for problem in (self._shared_channel(), self._period_problem(), *self._output_problems()):
            if problem:
                raise ValueError(problem)
        return self

    def _shared_channel(self) -> str:
        by_channel: dict[int, str] = {}
        for j in self.joints:
            other = by_channel.setdefault(j.channel, j.name)
            if other != j.name:
                board, pin = divmod(j.channel, pca9685.CHANNELS)
                where = f" (pin {pin} of board {board} of an i2c chain, counting from 0)" if board else ""
                return (
                    f"joints {other} and {j.name} are both on channel {j.channel}{where}; "
                    "give each joint its own channel"
                )
        return ""

    def _period_problem(self) -> str:
        if all(isinstance(o, SerialOutput) for o in self.outputs):
            return ""  # a serial controller makes its own period; pwm_frequency_hz is not used
        period_us = 1e6 / self.pwm_frequency_hz
        for j in self.joints:
            if j.pulse_max_us >= period_us:
                return (
                    f"joints.{j.name}: pulse_max_us {j.pulse_max_us:g} does not fit the PWM period of "
                    f"{period_us:.0f} µs at pwm_frequency_hz {self.pwm_frequency_hz:g}; lower the "
                    "frequency or the pulse"
                )
        return ""

    def _output_problems(self) -> list[str]:
        problems: list[str] = []
        kinds = [o.kind for o in self.outputs]
        if kinds.count("zenoh") > 1:
            problems.append("outputs: 'zenoh' is listed twice")
        seen: dict[object, int] = {}
        top = max(j.channel for j in self.joints)
        for i, output in enumerate(self.outputs):
            where = f"outputs[{i}]"
            if isinstance(output, I2cOutput):
                for address in output.address:
                    first = seen.setdefault(("i2c", output.bus, address), i)
                    if first != i:
                        problems.append(
                            f"{where}: board 0x{address:02x} on bus {output.bus} is also outputs[{first}]"
                        )
                boards = len(output.address)
                if top >= boards * pca9685.CHANNELS:
                    problems.append(
                        f"{where}: a joint is on channel {top}, but {boards} board(s) carry channels "
                        f"0–{boards * pca9685.CHANNELS - 1}; list the next board's address"
                    )
                try:
                    pca9685.prescale_for(self.pwm_frequency_hz, output.oscillator_hz)
                except ValueError as err:
                    problems.append(f"{where}.oscillator_hz: {err}")
            elif isinstance(output, SerialOutput):
                first = seen.setdefault(("serial", output.port), i)
                if first != i:
                    problems.append(f"{where}: port {output.port} is also outputs[{first}]")
                if top >= ssc32.CHANNELS:
                    problems.append(f"{where}: a joint is on channel {top}; an SSC-32 has channels 0–31")
                low, high = ssc32.PULSE_RANGE_US
                for j in self.joints:
                    if j.pulse_min_us < low or j.pulse_max_us > high:
                        problems.append(
                            f"{where}: joints.{j.name} pulses {j.pulse_min_us:g}–{j.pulse_max_us:g} µs "
                            f"leave the {low}–{high} µs an SSC-32 makes: keep the pulses within it "
                            "(calibrate the angle range to match) or drive the servo from an i2c board"
                        )
        return problems
