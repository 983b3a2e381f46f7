"""IO and RTDE register builtins: called as the compiled program calls them, and through small scripts."""

from __future__ import annotations

from typing import Any

import pytest

from tests.fakeur.urscript.library_host import call_builtin, make_host, run_script
from urdaemon.fakeur.urscript import lib_io as io
from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError
from urdaemon.fakeur.urscript.script_host import InputRegisters


def test_digital_outputs_land_in_their_groups_bits() -> None:
    host = make_host()
    call_builtin("set_standard_digital_out", host, 1, True)
    call_builtin("set_configurable_digital_out", host, 2, True)
    call_builtin("set_tool_digital_out", host, 1, True)
    assert host.arm.io.digital_out == (1 << 1) | (1 << 10) | (1 << 17)
    assert call_builtin("get_digital_out", host, 10) is True
    assert call_builtin("get_configurable_digital_out", host, 2) is True
    assert call_builtin("get_standard_digital_out", host, 2) is False
    call_builtin("set_digital_out", host, 17, False)
    assert call_builtin("get_tool_digital_out", host, 1) is False


def test_digital_inputs_read_the_input_word() -> None:
    host = make_host()
    host.arm.io.digital_in = (1 << 3) | (1 << 8) | (1 << 16)
    assert call_builtin("get_standard_digital_in", host, 3) is True
    assert call_builtin("get_configurable_digital_in", host, 0) is True
    assert call_builtin("get_tool_digital_in", host, 0) is True
    assert call_builtin("get_digital_in", host, 4) is False


@pytest.mark.parametrize(
    ("name", "args"),
    [
        ("set_standard_digital_out", (8, True)),
        ("set_tool_digital_out", (2, True)),
        ("set_digital_out", (18, True)),
        ("set_standard_digital_out", (0, "yes")),
        ("get_configurable_digital_in", (-1,)),
        ("set_standard_analog_out", (0, 1.5)),
        ("set_standard_analog_out", (2, 0.5)),
        ("set_tool_voltage", (5,)),
        ("read_input_integer_register", (48,)),
        ("read_input_boolean_register", (128,)),
        ("write_output_integer_register", (0, 2**31)),
        ("write_output_integer_register", (0, 1.5)),
        ("write_output_float_register", (0, "x")),
    ],
)
def test_bad_arguments_are_runtime_errors(name: str, args: tuple[Any, ...]) -> None:
    with pytest.raises(ScriptRuntimeError, match=name):
        call_builtin(name, make_host(), *args)


def test_analog_out_domains_and_tool_voltage() -> None:
    host = make_host()
    call_builtin("set_standard_analog_out", host, 1, 0.25)
    # set as a level of its domain (current: 4-20 mA), read back in amperes; volts once a voltage
    assert call_builtin("get_standard_analog_out", host, 1) == pytest.approx(0.008)
    assert host.arm.io.analog_out == [0.0, 0.25]
    call_builtin("set_analog_outputdomain", host, 1, 1)
    assert call_builtin("get_standard_analog_out", host, 1) == pytest.approx(2.5)
    assert call_builtin("get_analog_out", host, 1) == pytest.approx(2.5)
    call_builtin("set_standard_analog_input_domain", host, 0, 1)
    assert host.arm.io.analog_out_types == (1 << 3) | (1 << 0)
    call_builtin("set_analog_outputdomain", host, 1, 0)
    assert host.arm.io.analog_out_types == 1 << 0
    host.arm.io.analog_in = [1.0, 2.0]
    host.arm.io.tool_analog_in = [3.0, 4.0]
    assert [call_builtin("get_analog_in", host, n) for n in range(4)] == [1.0, 2.0, 3.0, 4.0]
    assert call_builtin("get_tool_analog_in", host, 1) == 4.0
    call_builtin("set_tool_voltage", host, 24)
    assert host.arm.io.tool_voltage == 24


def test_input_and_output_registers_are_separate() -> None:
    """ur_rtde's script reads its command from input_int_register_0 and writes its status to
    output_int_register_0: one shared register would overwrite the command with the status."""
    inputs = InputRegisters()
    host = make_host(input_registers=inputs)
    inputs.ints[0] = 7
    inputs.doubles[24] = 0.5
    inputs.bits[64] = True
    call_builtin("write_output_integer_register", host, 0, 1)
    call_builtin("write_output_float_register", host, 24, 2)
    call_builtin("write_output_boolean_register", host, 64, False)
    assert call_builtin("read_input_integer_register", host, 0) == 7
    assert call_builtin("read_input_float_register", host, 24) == 0.5
    assert call_builtin("read_input_boolean_register", host, 64) is True
    assert call_builtin("read_output_integer_register", host, 0) == 1
    assert call_builtin("read_output_float_register", host, 24) == 2.0
    assert call_builtin("read_output_boolean_register", host, 64) is False
    assert host.arm.io.registers_int == {0: 1}
    assert host.arm.io.registers_double == {24: 2.0}
    assert call_builtin("read_input_integer_register", host, 47) == 0
    assert call_builtin("read_output_boolean_register", host, 127) is False


def test_a_script_sets_outputs_and_echoes_a_register() -> None:
    host = make_host()
    host.input_registers.ints[24] = 41
    error = run_script(
        host,
        "set_digital_out(2, True)\n"
        "set_standard_analog_out(0, 0.5)\n"
        "write_output_integer_register(24, read_input_integer_register(24) + 1)\n",
    ).error
    assert error is None
    assert host.arm.io.digital_out == 1 << 2
    assert host.arm.io.analog_out[0] == 0.5
    assert host.arm.io.registers_int[24] == 42


def test_a_bad_address_stops_the_script_with_line_and_column() -> None:
    host = make_host()
    error = run_script(host, "x = 1\n  y = read_input_float_register(48)\n").error
    assert isinstance(error, ScriptRuntimeError)
    assert (error.line, error.column) == (2, 3)
    assert "read_input_float_register" in error.message


def test_input_actions_default_is_accepted_and_freedrive_is_refused_as_not_simulated() -> None:
    """On f5f0e26 the set_*_input_action family stopped the program with "not simulated"; "default" (what
    PolyScope's installation preamble writes) runs; "freedrive" would need something watching the inputs,
    so it stops the program saying so rather than being recorded and ignored."""
    from urdaemon.fakeur.urscript.lib_settings import settings_of

    host = make_host()
    error = run_script(
        host,
        'set_standard_digital_input_action(3, "default")\n'
        'set_tool_digital_input_action(1, "default")\n'
        'set_gp_boolean_input_action(100, "default")\n'
        'set_configurable_digital_input_action(0, "default")\n',
    ).error
    assert error is None
    assert settings_of(host.arm).input_actions == {}
    assert run_script(host, "set_input_actions_to_default()\n").error is None
    for call in (
        'set_standard_digital_input_action(3, "freedrive")',
        'set_tool_digital_input_action(1, "freedrive")',
        'set_gp_boolean_input_action(100, "freedrive")',
    ):
        error = run_script(host, call + "\n").error
        assert error is not None
        assert "not simulated" in error.message, call
    error = run_script(host, 'set_standard_digital_input_action(8, "freedrive")\n').error
    assert error is not None
    assert "0..7" in error.message
    error = run_script(host, 'set_tool_digital_input_action(0, "start")\n').error
    assert error is not None
    assert "freedrive" in error.message


def test_runstate_outputs_apply_when_programs_start_and_stop() -> None:
    """Recorded by the builtins; ``apply_runstate_outputs`` is what the controller calls at start/stop."""
    host = make_host()
    arm = host.arm
    error = run_script(
        host,
        "set_runstate_standard_digital_output_to_value(0, 2)\n"  # high when stopped
        "set_runstate_tool_digital_output_to_value(1, 3)\n"  # high while running, low when stopped
        "set_runstate_gp_boolean_output_to_value(70, 1)\n"  # low when stopped
        "set_runstate_standard_analog_output_to_value(1, 2)\n"  # maximum when stopped
        "set_runstate_standard_analog_output_to_value(0, 3)\n"  # maximum while running, minimum when stopped
        "set_runstate_configurable_digital_output_to_value(4, 0)\n",  # keep its value
    ).error
    assert error is None
    arm.io.registers_bit[70] = True
    arm.io.digital_out = 1 << 12
    arm.io.analog_out[1] = 0.25
    io.apply_runstate_outputs(arm, running=True)
    assert arm.io.digital_out == (1 << 12) | (1 << 17)
    assert arm.io.analog_out == [1.0, 0.25]
    io.apply_runstate_outputs(arm, running=False)
    assert arm.io.digital_out == (1 << 12) | (1 << 0)
    assert arm.io.registers_bit[70] is False
    assert arm.io.analog_out == [0.0, 1.0]
    error = run_script(host, "set_runstate_standard_digital_output_to_value(0, 4)\n").error
    assert error is not None
    assert "0..3" in error.message
    error = run_script(host, "set_runstate_standard_analog_output_to_value(0, 4)\n").error
    assert error is not None
    assert "0..3" in error.message


def test_analog_input_ranges_and_tool_domains() -> None:
    from urdaemon.fakeur.urscript.lib_settings import settings_of

    host = make_host()
    assert run_script(host, "set_tool_analog_input_domain(1, 0)\nset_analog_inputrange(0, 2)\n").error is None
    assert settings_of(host.arm).tool_analog_input_domain == [1, 0]
    assert host.arm.io.analog_out_types & 1 == 1  # standard input 0 in voltage mode
    assert run_script(host, "set_analog_inputrange(2, 2)\nset_analog_inputrange(3, 1)\n").error is None
    assert settings_of(host.arm).tool_analog_input_domain == [0, 1]
    error = run_script(host, "set_analog_inputrange(1, 3)\n").error
    assert error is not None
    assert "refused" in error.message
