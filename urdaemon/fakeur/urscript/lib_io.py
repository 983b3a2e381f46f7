"""URScript's IO builtins: digital and analog in/out, tool voltage, and the RTDE general purpose registers.

The controller's IO lives in ``host.arm.io`` (what RTDE and the primary interface report): digital outputs
and inputs as one bit word each (standard 0-7 in bits 0-7, configurable 0-7 in bits 8-15, tool 0-1 in
bits 16-17), the two standard analog outputs as the relative level ``set_standard_analog_out`` takes
(0..1, like RTDE's ``standard_analog_output_X`` inputs) and ``analog_out_types`` as RTDE's
``analog_io_types`` (bits 0-1: standard analog inputs, bits 2-3: outputs; 1 = voltage, 0 = current).
What reads an analog output back (``get_standard_analog_out``, RTDE's ``standard_analog_outputX``, the
primary interface's masterboard data) reads it in its domain's unit: :func:`analog_output_level`.

Registers (UR's RTDE guide): integer and float registers 0..47, boolean registers 0..127, in two separate
sets. The *input* registers are written by RTDE clients and read by ``read_input_*_register`` (they are
``host.input_registers``, kept by the controller); the *output* registers are written by
``write_output_*_register``, read back by ``read_output_*_register`` and published as RTDE
``output_*_register_X`` (they are ``arm.io.registers_int/double/bit``). A register never written reads 0,
0.0 or False. An address outside its range, or a value of the wrong kind, is a runtime error.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Final

from urdaemon.fakeur.fake_arm import FakeArm, IoState
from urdaemon.fakeur.urscript.lib_settings import INPUT_ACTIONS, settings_of
from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError, builtin
from urdaemon.fakeur.urscript.script_host import ScriptHost
from urdaemon.model import (
    CONFIGURABLE_IO_SHIFT,
    IO_SIZES,
    STANDARD_IO_SHIFT,
    TOOL_IO_SHIFT,
    TOOL_VOLTAGES,
    analog_output_value,
)

__all__ = [
    "BIT_REGISTERS",
    "IO_DIGITAL_IN_GET",
    "IO_DIGITAL_OUT_GET",
    "IO_DIGITAL_OUT_SET",
    "NUMBER_REGISTERS",
    "TOOL_VOLTAGES",  # model.py's, kept importable here
    "analog_output_level",
]

NUMBER_REGISTERS: Final = 48
"""Integer and float registers per direction: addresses 0..47."""
BIT_REGISTERS: Final = 128
"""Boolean registers per direction: addresses 0..127 (64..127 are RTDE's ``*_bit_register_X``)."""
_VOLTAGES: Final = ", ".join(str(v) for v in TOOL_VOLTAGES)
_INT32: Final = (-(2**31), 2**31 - 1)

IO_DIGITAL_OUT_GET: Final = "_digital_out_get"
"""Registry names of the controller's IO variables (``digital_out[n]`` read and write, ``digital_in[n]``
read): not in the builtin table, so no program can call them by name; the compiler turns the variables'
uses into calls of these."""
IO_DIGITAL_OUT_SET: Final = "_digital_out_set"
IO_DIGITAL_IN_GET: Final = "_digital_in_get"

# (first bit in the word, how many) of each digital IO group
_STANDARD: Final = (STANDARD_IO_SHIFT, IO_SIZES["digital"])
_CONFIGURABLE: Final = (CONFIGURABLE_IO_SHIFT, IO_SIZES["configurable"])
_TOOL: Final = (TOOL_IO_SHIFT, IO_SIZES["tool"])
_ALL: Final = (STANDARD_IO_SHIFT, TOOL_IO_SHIFT + IO_SIZES["tool"])
"""The deprecated ``*_digital_*(n)`` numbering: 0-7 standard, 8-15 configurable, 16-17 tool."""


def _index(function: str, value: Any, count: int) -> int:
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if value.__class__ is not int or not 0 <= value < count:
        raise ScriptRuntimeError(f"{function}: {value!r} is not in 0..{count - 1}")
    return int(value)


def _level(function: str, value: Any) -> bool:
    if isinstance(value, bool):
        return value
    if isinstance(value, int) and value in (0, 1):
        return bool(value)
    raise ScriptRuntimeError(f"{function}: expected True or False, got {value!r}")


def _number(function: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScriptRuntimeError(f"{function}: expected a number, got {value!r}")
    return float(value)


def _register(name: str, function: Callable[..., Any]) -> None:
    """Register ``function`` (made for a row of one of the tables below) as builtin ``name``."""
    function.__name__ = function.__qualname__ = name
    builtin(name)(function)


# ---- digital ------------------------------------------------------------------------------------------


def _set_bit(host: ScriptHost, function: str, group: tuple[int, int], n: Any, b: Any) -> None:
    bit = 1 << (group[0] + _index(function, n, group[1]))
    io = host.arm.io
    io.digital_out = io.digital_out | bit if _level(function, b) else io.digital_out & ~bit


def _get_bit(word: int, function: str, group: tuple[int, int], n: Any) -> bool:
    return bool(word >> (group[0] + _index(function, n, group[1])) & 1)


FLAGS = 32
"""Program flags 0-31: internal digital outputs that keep their value between programs."""


@builtin("set_flag")
def set_flag(host: ScriptHost, n: Any, b: Any) -> None:
    index = _index("set_flag", n, FLAGS)
    io = host.arm.io
    io.flags = io.flags | (1 << index) if _level("set_flag", b) else io.flags & ~(1 << index)


@builtin("get_flag")
def get_flag(host: ScriptHost, n: Any) -> bool:
    return bool(host.arm.io.flags >> _index("get_flag", n, FLAGS) & 1)


_DIGITAL_GROUPS: Final = {"standard_": _STANDARD, "configurable_": _CONFIGURABLE, "tool_": _TOOL, "": _ALL}
"""The digital IO groups by the infix of their builtins' names: ``set_<infix>digital_out(n, b)``,
``get_<infix>digital_out(n)`` and ``get_<infix>digital_in(n)``; "" is the deprecated numbering."""


def _digital_builtins(infix: str, group: tuple[int, int]) -> None:
    """Register the three digital IO builtins of one group (``_DIGITAL_GROUPS``)."""
    set_name, get_out_name, get_in_name = (
        f"set_{infix}digital_out",
        f"get_{infix}digital_out",
        f"get_{infix}digital_in",
    )

    def set_out(host: ScriptHost, n: Any, b: Any) -> None:
        _set_bit(host, set_name, group, n, b)

    def get_out(host: ScriptHost, n: Any) -> bool:
        return _get_bit(host.arm.io.digital_out, get_out_name, group, n)

    def get_in(host: ScriptHost, n: Any) -> bool:
        return _get_bit(host.arm.io.digital_in, get_in_name, group, n)

    _register(set_name, set_out)
    _register(get_out_name, get_out)
    _register(get_in_name, get_in)


for _infix, _group in _DIGITAL_GROUPS.items():
    _digital_builtins(_infix, _group)


# ---- the controller's IO variables (``digital_out[n]``) -----------------------------------------------

_LEGACY: Final = (_STANDARD, _TOOL)
"""The legacy IO variables' numbering (CB2's): 0-7 the standard IO (bits 0-7), 8-9 the tool IO (bits
16-17). Configurable IO has no number in it: it came with CB3, after this syntax.

Evidence: python-urx's ``set_digital_out(8, True)`` sends ``digital_out[8]=True``, and a CB3 user drove
the tool output with it (it opened and closed the gripper; python-urx issue #8, 2016) while bit 8 of the
secondary interface's ``digitalOutputBits`` (configurable output 0 on CB3) stayed 0.
"""


def _legacy_bit(name: str, n: Any) -> int:
    standard, tool = _LEGACY
    index = _index(name, n, standard[1] + tool[1])
    return standard[0] + index if index < standard[1] else tool[0] + index - standard[1]


@builtin(IO_DIGITAL_OUT_GET)
def digital_out_get(host: ScriptHost, n: Any) -> bool:
    """``digital_out[n]`` read (n: 0-7 standard outputs, 8-9 tool outputs)."""
    return bool(host.arm.io.digital_out >> _legacy_bit("digital_out", n) & 1)


@builtin(IO_DIGITAL_OUT_SET)
def digital_out_set(host: ScriptHost, n: Any, b: Any) -> None:
    """``digital_out[n] = b`` (n: 0-7 standard outputs, 8-9 tool outputs; b True/False or 1/0)."""
    bit = 1 << _legacy_bit("digital_out", n)
    io = host.arm.io
    io.digital_out = io.digital_out | bit if _level("digital_out", b) else io.digital_out & ~bit


@builtin(IO_DIGITAL_IN_GET)
def digital_in_get(host: ScriptHost, n: Any) -> bool:
    """``digital_in[n]`` read (n: 0-7 standard inputs, 8-9 tool inputs)."""
    return bool(host.arm.io.digital_in >> _legacy_bit("digital_in", n) & 1)


# ---- analog and tool voltage -----------------------------------------------------------------------------


_ANALOG_OUTS: Final = ("standard_analog_out", "analog_out")
"""``set_<name>(n, f)`` sets analog output ``n`` (0..1) to the relative level ``f`` (0..1) of its domain,
``get_<name>(n)`` reads it back in amperes or volts; ``analog_out`` is the deprecated name of the same
outputs."""


def analog_output_level(io: IoState, pin: int) -> float:
    """Standard analog output ``pin`` (0..1) in its domain's unit: amperes in the current domain (4-20
    mA), volts in the voltage domain (0-10 V), as UR's script manual and RTDE guide give it."""
    return analog_output_value(io.analog_out[pin], bool((io.analog_out_types >> (pin + 2)) & 1))


_ANALOG_INS: Final = {"get_standard_analog_in": "analog_in", "get_tool_analog_in": "tool_analog_in"}
"""The analog input readers (inputs 0..1) by the ``IoState`` field they read."""
_DOMAINS: Final = {"set_analog_outputdomain": 2, "set_standard_analog_input_domain": 0}
"""``name(port, domain)``: port 0..1 in current (``domain`` 0, 4-20 mA) or voltage (1, 0-10 V) mode, the
analog outputs' (bits 2-3 of ``analog_out_types``) and the standard analog inputs' (bits 0-1), by the
first bit of the pair."""


def _analog_out_builtins(name: str) -> None:
    set_name, get_name = f"set_{name}", f"get_{name}"

    def set_out(host: ScriptHost, n: Any, f: Any) -> None:
        pin = _index(set_name, n, 2)
        level = _number(set_name, f)
        if not 0.0 <= level <= 1.0:
            raise ScriptRuntimeError(f"{set_name}: level {level:g} is not in 0..1")
        host.arm.io.analog_out[pin] = level

    def get_out(host: ScriptHost, n: Any) -> float:
        return analog_output_level(host.arm.io, _index(get_name, n, 2))

    _register(set_name, set_out)
    _register(get_name, get_out)


def _analog_in_builtin(name: str, field: str) -> None:
    def get_in(host: ScriptHost, n: Any) -> float:
        levels: list[float] = getattr(host.arm.io, field)
        return levels[_index(name, n, 2)]

    _register(name, get_in)


def _domain_builtin(name: str, first_bit: int) -> None:
    def set_domain(host: ScriptHost, port: Any, domain: Any) -> None:
        _set_domain(host, name, first_bit, port, domain)

    _register(name, set_domain)


@builtin("get_analog_in")
def get_analog_in(host: ScriptHost, n: Any) -> float:
    """Deprecated numbering: 0-1 standard analog inputs, 2-3 tool analog inputs."""
    pin = _index("get_analog_in", n, 4)
    io = host.arm.io
    return io.analog_in[pin] if pin < 2 else io.tool_analog_in[pin - 2]


def _set_domain(host: ScriptHost, function: str, first_bit: int, port: Any, domain: Any) -> None:
    bit = 1 << (first_bit + _index(function, port, 2))
    voltage = _index(function, domain, 2) == 1
    io = host.arm.io
    io.analog_out_types = io.analog_out_types | bit if voltage else io.analog_out_types & ~bit


for _name in _ANALOG_OUTS:
    _analog_out_builtins(_name)
for _name, _field in _ANALOG_INS.items():
    _analog_in_builtin(_name, _field)
for _name, _first_bit in _DOMAINS.items():
    _domain_builtin(_name, _first_bit)


@builtin("set_tool_voltage")
def set_tool_voltage(host: ScriptHost, voltage: Any) -> None:
    """Tool output voltage: 0, 12 or 24 V."""
    if isinstance(voltage, float) and voltage.is_integer():
        voltage = int(voltage)
    if isinstance(voltage, bool) or voltage not in TOOL_VOLTAGES:
        raise ScriptRuntimeError(f"set_tool_voltage: {voltage!r} V is not one of {_VOLTAGES}")
    host.arm.io.tool_voltage = int(voltage)


# ---- RTDE registers --------------------------------------------------------------------------------------


_Registers = Callable[[ScriptHost], dict[int, Any]]
"""The register set a reader reads, of the host."""
_REGISTER_READS: Final[dict[str, tuple[_Registers, int, Any]]] = {
    "read_input_integer_register": (lambda host: host.input_registers.ints, NUMBER_REGISTERS, 0),
    "read_input_float_register": (lambda host: host.input_registers.doubles, NUMBER_REGISTERS, 0.0),
    "read_input_boolean_register": (lambda host: host.input_registers.bits, BIT_REGISTERS, False),
    "read_output_integer_register": (lambda host: host.arm.io.registers_int, NUMBER_REGISTERS, 0),
    "read_output_float_register": (lambda host: host.arm.io.registers_double, NUMBER_REGISTERS, 0.0),
    "read_output_boolean_register": (lambda host: host.arm.io.registers_bit, BIT_REGISTERS, False),
}
"""``name(address)`` → (the registers it reads, how many there are, what one never written reads)."""


def _register_read(
    name: str, registers: Callable[[ScriptHost], dict[int, Any]], count: int, unset: Any
) -> None:
    def read(host: ScriptHost, address: Any) -> Any:
        return registers(host).get(_index(name, address, count), unset)

    _register(name, read)


for _name, (_registers, _count, _unset) in _REGISTER_READS.items():
    _register_read(_name, _registers, _count, _unset)


@builtin("write_output_integer_register")
def write_output_integer_register(host: ScriptHost, address: Any, value: Any) -> None:
    index = _index("write_output_integer_register", address, NUMBER_REGISTERS)
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if value.__class__ is not int or not _INT32[0] <= value <= _INT32[1]:
        raise ScriptRuntimeError(f"write_output_integer_register: {value!r} is not a 32-bit integer")
    host.arm.io.registers_int[index] = value


@builtin("write_output_float_register")
def write_output_float_register(host: ScriptHost, address: Any, value: Any) -> None:
    index = _index("write_output_float_register", address, NUMBER_REGISTERS)
    host.arm.io.registers_double[index] = _number("write_output_float_register", value)


@builtin("write_output_boolean_register")
def write_output_boolean_register(host: ScriptHost, address: Any, value: Any) -> None:
    index = _index("write_output_boolean_register", address, BIT_REGISTERS)
    host.arm.io.registers_bit[index] = _level("write_output_boolean_register", value)


# ---- analog input ranges ----------------------------------------------------------------------------------


@builtin("set_tool_analog_input_domain")
def set_tool_analog_input_domain(host: ScriptHost, port: Any, domain: Any) -> None:
    """Tool analog input ``port`` (0..1) in current (``domain`` 0, 4-20 mA) or voltage (1, 0-10 V) mode."""
    pin = _index("set_tool_analog_input_domain", port, 2)
    settings_of(host.arm).tool_analog_input_domain[pin] = _index("set_tool_analog_input_domain", domain, 2)


@builtin("set_analog_inputrange")
def set_analog_inputrange(host: ScriptHost, port: Any, range: Any) -> None:
    """Deprecated numbering: ports 0-1 the controller's inputs (range 0 or 2: 0-10 V; the old bipolar
    ranges 1 and 3 are refused as on e-Series), 2-3 the tool's (range 0 or 1: 0-10 V, 2: 4-20 mA)."""
    pin = _index("set_analog_inputrange", port, 4)
    code = _index("set_analog_inputrange", range, 4)
    if pin < 2:
        if code not in (0, 2):
            raise ScriptRuntimeError(f"set_analog_inputrange: range {code} is refused (0-10 V: 0 or 2)")
        _set_domain(host, "set_analog_inputrange", 0, pin, 1)
    else:
        if code == 3:
            raise ScriptRuntimeError("set_analog_inputrange: tool inputs take range 0, 1 or 2, got 3")
        settings_of(host.arm).tool_analog_input_domain[pin - 2] = 0 if code == 2 else 1


# ---- input actions and run-state outputs ----------------------------------------------------------------

_INPUT_GROUPS: Final = {
    "standard": IO_SIZES["digital"],
    "configurable": IO_SIZES["configurable"],
    "tool": IO_SIZES["tool"],
    "gp_boolean": BIT_REGISTERS,
}


def _input_action(host: ScriptHost, function: str, group: str, port: Any, action: Any) -> None:
    pin = _index(function, port, _INPUT_GROUPS[group])
    if action not in INPUT_ACTIONS:
        raise ScriptRuntimeError(f'{function}: action must be "default" or "freedrive", got {action!r}')
    if action == "freedrive":
        raise ScriptRuntimeError(
            f'{function}: the "freedrive" action is not simulated by the fake controller: nothing watches '
            "its inputs to start freedrive"
        )
    actions = settings_of(host.arm).input_actions
    if action == "default":
        actions.pop((group, pin), None)
    else:
        actions[(group, pin)] = action


_INPUT_ACTION_GROUPS: Final = ("standard", "configurable", "tool", "gp_boolean")
"""``set_<group>_(digital_)input_action(port, action)``: what input ``port`` of the group does when high:
``"default"`` (nothing); ``"freedrive"`` stops the program with "not simulated" (nothing watches the
fake's inputs to start freedrive). ``gp_boolean``: the general purpose boolean input registers."""


def _input_action_builtin(group: str) -> None:
    name = f"set_{group}_input_action" if group == "gp_boolean" else f"set_{group}_digital_input_action"

    def set_action(host: ScriptHost, port: Any, action: Any) -> None:
        _input_action(host, name, group, port, action)

    _register(name, set_action)


for _group_name in _INPUT_ACTION_GROUPS:
    _input_action_builtin(_group_name)


@builtin("set_input_actions_to_default")
def set_input_actions_to_default(host: ScriptHost) -> None:
    settings_of(host.arm).input_actions.clear()


RUNSTATE_DIGITAL: Final = (0, 1, 2, 3)
"""A digital output's run-state choice: 0 keep its value, 1 low while no program runs, 2 high while no
program runs, 3 high while a program runs and low while none does."""
RUNSTATE_ANALOG: Final = (0, 1, 2, 3)
"""An analog output's run-state choice: 0 keep its value, 1 its minimum while no program runs, 2 its
maximum while no program runs, 3 its maximum while a program runs and its minimum while none does."""
_OUTPUT_GROUPS: Final = {
    "standard": _STANDARD,
    "configurable": _CONFIGURABLE,
    "tool": _TOOL,
    "gp_boolean": (0, BIT_REGISTERS),
    "analog": (0, IO_SIZES["analog"]),
}


def _runstate(host: ScriptHost, function: str, group: str, output_id: Any, state: Any) -> None:
    output = _index(function, output_id, _OUTPUT_GROUPS[group][1])
    choices = RUNSTATE_ANALOG if group == "analog" else RUNSTATE_DIGITAL
    choice = _index(function, state, len(choices))
    outputs = settings_of(host.arm).runstate_outputs
    if choice == 0:
        outputs.pop((group, output), None)
    else:
        outputs[(group, output)] = choice


def apply_runstate_outputs(arm: FakeArm, running: bool) -> None:
    """Set every output that has a run-state choice as it says for a program ``running`` or not.

    The controller calls this when a program starts (``running``) and when it stops (not ``running``).
    """
    outputs = settings_of(arm).runstate_outputs
    if not outputs:
        return
    io = arm.io
    for (group, output), choice in outputs.items():
        if choice in (1, 2) and running:
            continue
        high = choice == 2 or (choice == 3 and running)
        if group == "analog":
            io.analog_out[output] = 1.0 if high else 0.0
        elif group == "gp_boolean":
            io.registers_bit[output] = high
        else:
            bit = 1 << (_OUTPUT_GROUPS[group][0] + output)
            io.digital_out = io.digital_out | bit if high else io.digital_out & ~bit


_RUNSTATE_BUILTINS: Final = {
    "set_runstate_standard_digital_output_to_value": "standard",
    "set_runstate_configurable_digital_output_to_value": "configurable",
    "set_runstate_tool_digital_output_to_value": "tool",
    "set_runstate_gp_boolean_output_to_value": "gp_boolean",
    "set_runstate_standard_analog_output_to_value": "analog",
}
"""``name(outputId, state)`` → the output group whose output ``outputId`` does as programs start and
stop what ``state`` says (:data:`RUNSTATE_DIGITAL`, :data:`RUNSTATE_ANALOG` for the analog outputs)."""


def _runstate_builtin(name: str, group: str) -> None:
    def set_runstate(host: ScriptHost, outputId: Any, state: Any) -> None:
        _runstate(host, name, group, outputId, state)

    _register(name, set_runstate)


for _name, _group_name in _RUNSTATE_BUILTINS.items():
    _runstate_builtin(_name, _group_name)
