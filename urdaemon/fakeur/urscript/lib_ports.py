"""``read_port_*``/``write_port_*``: a program's access to the controller's own Modbus server map.

UR documents that map for its Modbus TCP server on port 502 ("Modbus server", universal-robots.com
articles): the fake gives programs the part of it that is the arm's IO (``arm.io``) and state. Addresses
the fake maps:

Registers (16 bits; ``read_port_register`` returns them signed, -32768..32767, as the manual says;
``write_port_register`` takes -32768..65535)
  0 inputs (bits 0-7 standard, 8-9 tool; R) · 1 outputs (same bits; R/W) · 2 / 3 set / clear those
  outputs by mask (W) · 4, 6 analog inputs 0-1 and 8, 10 the tool's (mA or mV; R) · 5, 7, 9, 11 their
  domains (0 current, 1 voltage; R/W) · 16, 18 analog outputs 0-1 (mA or mV; R/W) · 17, 19 their domains
  (R/W) · 20 tool output voltage (V; R/W) · 21 tool input bits (R) · 22 tool output bits (R/W) · 30
  configurable inputs (R) · 31 configurable outputs (R/W) · 32 / 33 set / clear those by mask (W) ·
  128-255 general purpose registers (R/W) · 256-258 version major, minor, robot mode (R) · 260-262
  powered, protective stop, emergency stop (R) · 270-275 joint positions (mrad; R) · 280-285 joint
  speeds (mrad/s; R) · 400-405 TCP pose (0.1 mm, mrad; R) · 410-415 TCP speed (mm/s, mrad/s; R).
Coils (bits)
  0-15 the bits of register 0 (R) · 16-31 of register 1 (R/W) · 32-47 / 48-63 set / clear the output
  of the same bit (W) · 128-135 configurable inputs (R) · 136-143 configurable outputs (R/W) ·
  300-427 the general purpose boolean input registers (R) · 500-627 the output ones (R/W).

Anything else (Euromap67 at 24-29 and coils 64-127, reserved addresses, a write to a read-only one) is
a runtime error naming the address: the fake never answers with a made-up value.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, Final

from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.urscript.lib_motion import tcp_pose, tool_speed
from urdaemon.fakeur.urscript.lib_settings import settings_of
from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError, builtin
from urdaemon.fakeur.urscript.script_host import ScriptHost
from urdaemon.model import CONFIGURABLE_IO_SHIFT, TOOL_IO_SHIFT, TOOL_VOLTAGES, RobotMode, SafetyMode

__all__ = ["GENERAL_PURPOSE"]

GENERAL_PURPOSE: Final = range(128, 256)
"""The general purpose 16-bit registers."""
ANALOG_CURRENT_MA: Final = (4.0, 20.0)
"""mA: an analog output's range in current mode (its relative level 0..1 maps onto it)."""
ANALOG_VOLTAGE_MV: Final = (0.0, 10000.0)
"""mV: an analog output's range in voltage mode."""

# bit positions in arm.io's words: standard 0-7, configurable 8-15, tool 16-17 (model.py's)
_TOOL_SHIFT: Final = TOOL_IO_SHIFT
_CONFIGURABLE_SHIFT: Final = CONFIGURABLE_IO_SHIFT
_VOLTAGES: Final = ", ".join(str(v) for v in TOOL_VOLTAGES)


def _address(function: str, value: Any) -> int:
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if value.__class__ is not int or value < 0:
        raise ScriptRuntimeError(f"{function}: address must be an integer >= 0, got {value!r}")
    return int(value)


def _box_word(word: int) -> int:
    """An arm.io bit word as registers 0 and 1 show it: bits 0-7 standard, 8-9 tool."""
    return (word & 0xFF) | ((word >> _TOOL_SHIFT) & 0x3) << 8


def _set_box_word(arm: FakeArm, word: int) -> None:
    keep = arm.io.digital_out & ~(0xFF | 0x3 << _TOOL_SHIFT)
    arm.io.digital_out = keep | (word & 0xFF) | ((word >> 8) & 0x3) << _TOOL_SHIFT


def _analog_out(arm: FakeArm, pin: int) -> int:
    voltage = bool(arm.io.analog_out_types >> (2 + pin) & 1)
    low, high = ANALOG_VOLTAGE_MV if voltage else ANALOG_CURRENT_MA
    return round(low + arm.io.analog_out[pin] * (high - low))


def _write_analog_out(arm: FakeArm, pin: int, value: int) -> None:
    voltage = bool(arm.io.analog_out_types >> (2 + pin) & 1)
    low, high = ANALOG_VOLTAGE_MV if voltage else ANALOG_CURRENT_MA
    if not low <= value <= high:
        unit = "mV" if voltage else "mA"
        raise ScriptRuntimeError(f"write_port_register: {value} {unit} is outside {low:g}..{high:g} {unit}")
    arm.io.analog_out[pin] = (value - low) / (high - low)


def _domain_bit(arm: FakeArm, bit: int) -> int:
    return arm.io.analog_out_types >> bit & 1


def _set_domain_bit(arm: FakeArm, bit: int, value: int) -> None:
    if value not in (0, 1):
        raise ScriptRuntimeError(f"write_port_register: a domain is 0 (current) or 1 (voltage), got {value}")
    types = arm.io.analog_out_types
    arm.io.analog_out_types = types | 1 << bit if value else types & ~(1 << bit)


def _milli(value: float) -> int:
    return round(value * 1000.0) if math.isfinite(value) else 0


Reader = Callable[[ScriptHost], float]
"""How one register of the map is read from the host's arm."""


def _scaled(values: Callable[[FakeArm], Sequence[float]], index: int, scale: float) -> Reader:
    """Reads element ``index`` of ``values(arm)`` times ``scale``, rounded (0 if it is not finite)."""

    def read(host: ScriptHost) -> float:
        value = values(host.arm)[index] * scale
        return round(value) if math.isfinite(value) else 0

    return read


def _readers() -> dict[int, Reader]:
    """Every readable register but the general purpose ones, built once."""
    table: dict[int, Reader] = {
        0: lambda h: _box_word(h.arm.io.digital_in),
        1: lambda h: _box_word(h.arm.io.digital_out),
        4: lambda h: _milli(h.arm.io.analog_in[0]),
        5: lambda h: _domain_bit(h.arm, 0),
        6: lambda h: _milli(h.arm.io.analog_in[1]),
        7: lambda h: _domain_bit(h.arm, 1),
        8: lambda h: _milli(h.arm.io.tool_analog_in[0]),
        9: lambda h: settings_of(h.arm).tool_analog_input_domain[0],
        10: lambda h: _milli(h.arm.io.tool_analog_in[1]),
        11: lambda h: settings_of(h.arm).tool_analog_input_domain[1],
        16: lambda h: _analog_out(h.arm, 0),
        17: lambda h: _domain_bit(h.arm, 2),
        18: lambda h: _analog_out(h.arm, 1),
        19: lambda h: _domain_bit(h.arm, 3),
        20: lambda h: h.arm.io.tool_voltage,
        21: lambda h: h.arm.io.digital_in >> _TOOL_SHIFT & 0x3,
        22: lambda h: h.arm.io.digital_out >> _TOOL_SHIFT & 0x3,
        30: lambda h: h.arm.io.digital_in >> _CONFIGURABLE_SHIFT & 0xFF,
        31: lambda h: h.arm.io.digital_out >> _CONFIGURABLE_SHIFT & 0xFF,
        256: lambda h: h.version[0],
        257: lambda h: h.version[1],
        258: lambda h: int(h.arm.robot_mode),
        260: lambda h: int(h.arm.robot_mode not in (RobotMode.POWER_OFF, RobotMode.BOOTING)),
        261: lambda h: int(h.arm.safety_mode is SafetyMode.PROTECTIVE_STOP),
        262: lambda h: int(
            h.arm.safety_mode in (SafetyMode.ROBOT_EMERGENCY_STOP, SafetyMode.SYSTEM_EMERGENCY_STOP)
        ),
    }
    for i in range(6):
        table[270 + i] = _scaled(lambda arm: arm.q, i, 1000.0)
        table[280 + i] = _scaled(lambda arm: arm.qd, i, 1000.0)
        table[400 + i] = _scaled(lambda arm: tcp_pose(arm, arm.q), i, 10000.0 if i < 3 else 1000.0)
        table[410 + i] = _scaled(lambda arm: tool_speed(arm, arm.q, arm.qd), i, 1000.0)
    return table


_READERS: Final = _readers()


def _signed(value: int) -> int:
    """A register's 16 bits as the signed integer ``read_port_register`` returns (-32768..32767)."""
    value &= 0xFFFF
    return value - 0x10000 if value & 0x8000 else value


def _read_register(host: ScriptHost, address: int) -> int:
    if address in GENERAL_PURPOSE:
        return _signed(settings_of(host.arm).port_registers.get(address, 0))
    read = _READERS.get(address)
    if read is None:
        raise ScriptRuntimeError(f"read_port_register: address {address} is not readable on the fake's map")
    return _signed(int(read(host)))


def _write_register(host: ScriptHost, address: int, value: int) -> None:
    arm = host.arm
    io = arm.io
    if address in GENERAL_PURPOSE:
        settings_of(arm).port_registers[address] = value
    elif address == 1:
        _set_box_word(arm, value)
    elif address in (2, 3):
        current = _box_word(io.digital_out)
        _set_box_word(arm, current | value if address == 2 else current & ~value)
    elif address in (5, 7):
        _set_domain_bit(arm, (address - 5) // 2, value)
    elif address in (9, 11):
        if value not in (0, 1):
            raise ScriptRuntimeError(f"write_port_register: a domain is 0 or 1, got {value}")
        settings_of(arm).tool_analog_input_domain[(address - 9) // 2] = value
    elif address in (16, 18):
        _write_analog_out(arm, (address - 16) // 2, value)
    elif address in (17, 19):
        _set_domain_bit(arm, 2 + (address - 17) // 2, value)
    elif address == 20:
        if value not in TOOL_VOLTAGES:
            raise ScriptRuntimeError(f"write_port_register: tool voltage {value} V is not one of {_VOLTAGES}")
        io.tool_voltage = value
    elif address == 22:
        io.digital_out = io.digital_out & ~(0x3 << _TOOL_SHIFT) | (value & 0x3) << _TOOL_SHIFT
    elif address in (31, 32, 33):
        current = io.digital_out >> _CONFIGURABLE_SHIFT & 0xFF
        word = {31: value, 32: current | value, 33: current & ~value}[address] & 0xFF
        io.digital_out = io.digital_out & ~(0xFF << _CONFIGURABLE_SHIFT) | word << _CONFIGURABLE_SHIFT
    else:
        raise ScriptRuntimeError(f"write_port_register: address {address} is not writable on the fake's map")


@builtin("read_port_register")
def read_port_register(host: ScriptHost, address: Any) -> int:
    """The register at ``address`` of the controller's Modbus map, signed (see the module's table)."""
    return _read_register(host, _address("read_port_register", address))


@builtin("write_port_register")
def write_port_register(host: ScriptHost, address: Any, value: Any) -> None:
    """Write ``value`` (-32768..65535: its low 16 bits) to the register at ``address``."""
    index = _address("write_port_register", address)
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if value.__class__ is not int or not -0x8000 <= value <= 0xFFFF:
        raise ScriptRuntimeError(f"write_port_register: {value!r} is not a 16-bit value")
    _write_register(host, index, int(value) & 0xFFFF)


@builtin("read_port_bit")
def read_port_bit(host: ScriptHost, address: Any) -> bool:
    """The coil at ``address`` of the controller's Modbus map (see the module's table)."""
    index = _address("read_port_bit", address)
    if index < 32:
        return bool(_read_register(host, index // 16) >> (index % 16) & 1)
    if 128 <= index < 144:
        return bool(_read_register(host, 30 if index < 136 else 31) >> (index % 8) & 1)
    if 300 <= index < 428:
        return host.input_registers.bits.get(index - 300, False)
    if 500 <= index < 628:
        return host.arm.io.registers_bit.get(index - 500, False)
    raise ScriptRuntimeError(f"read_port_bit: address {index} is not readable on the fake's map")


@builtin("write_port_bit")
def write_port_bit(host: ScriptHost, address: Any, value: Any) -> None:
    """Set the coil at ``address`` (outputs and the output boolean registers; see the module's table)."""
    index = _address("write_port_bit", address)
    if isinstance(value, int) and not isinstance(value, bool) and value in (0, 1):
        value = bool(value)
    if not isinstance(value, bool):
        raise ScriptRuntimeError(f"write_port_bit: expected True or False, got {value!r}")
    if 16 <= index < 64:
        bit = 1 << (index % 16)
        if index >= 32 and not value:
            return  # a mask bit written low changes nothing
        current = _read_register(host, 1)
        high = value if index < 32 else index < 48
        _write_register(host, 1, current | bit if high else current & ~bit)
    elif 136 <= index < 144:
        current = _read_register(host, 31)
        bit = 1 << (index - 136)
        _write_register(host, 31, current | bit if value else current & ~bit)
    elif 500 <= index < 628:
        host.arm.io.registers_bit[index - 500] = value
    else:
        raise ScriptRuntimeError(f"write_port_bit: address {index} is not writable on the fake's map")
