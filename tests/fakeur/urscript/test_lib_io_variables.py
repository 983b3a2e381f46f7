"""The controller's legacy IO variables: ``digital_out[n]`` (read, assigned) and ``digital_in[n]`` (read).

Reproduction before the fix: python-urx's ``set_digital_out(2, True)`` sends the line
``digital_out[2]=True``; the fake refused it with ``compile_error_name_not_found:digital_out``.
"""

from __future__ import annotations

from typing import Any

import pytest

from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.urscript import ScriptCompileError, compile_program
from urdaemon.fakeur.urscript.script_host import ScriptHost

DT = 0.008


def _host() -> ScriptHost:
    model = load_ur_model("ur10")
    return ScriptHost(FakeArm(model, model.dh, powered=True), step_time=DT, series="cb3", version=(3, 15))


def _run(host: ScriptHost, text: str, cycles: int = 20) -> Any:
    """Run a script to its end as a CB3 3.15 controller; the run (its error is None if it ended well)."""
    run = compile_program(text, series="cb3", version=(3, 15)).start(host)
    for _ in range(cycles):
        if run.done:
            break
        run.step()
    assert run.done
    return run


def test_python_urx_line_sets_the_standard_output_bit() -> None:
    host = _host()
    run = _run(host, "digital_out[2]=True")
    assert run.error is None
    assert host.arm.io.digital_out == 1 << 2
    run = _run(host, "digital_out[2]=False")
    assert run.error is None
    assert host.arm.io.digital_out == 0


def test_outputs_8_and_9_are_the_tool_outputs() -> None:
    """CB2 numbering, which a CB3 keeps for these variables: python-urx issue #8 drove the tool output
    (a gripper) with ``digital_out[8]`` while the configurable output 0 (bit 8) stayed off."""
    host = _host()
    assert _run(host, "digital_out[8] = True\ndigital_out[9] = 1\ndigital_out[7] = True").error is None
    assert host.arm.io.digital_out == (1 << 16) | (1 << 17) | (1 << 7)


def test_reads_follow_the_io_words_and_other_builtins() -> None:
    host = _host()
    host.arm.io.digital_in = (1 << 3) | (1 << 17)
    text = (
        "set_standard_digital_out(5, True)\n"
        "set_tool_digital_out(0, True)\n"
        "write_output_boolean_register(0, digital_out[5])\n"
        "write_output_boolean_register(1, digital_out[8])\n"
        "write_output_boolean_register(2, digital_out[6])\n"
        "write_output_boolean_register(3, digital_in[3])\n"
        "write_output_boolean_register(4, digital_in[9])\n"
        "write_output_boolean_register(5, digital_in[8] or digital_in[4])\n"
    )
    assert _run(host, text).error is None
    bits = host.arm.io.registers_bit
    assert [bits[i] for i in range(6)] == [True, True, False, True, True, False]


@pytest.mark.parametrize("text", ["digital_out[10] = True", "x = digital_in[-1]", "digital_out[0] = 2"])
def test_a_bad_index_or_level_is_a_runtime_error(text: str) -> None:
    host = _host()
    run = _run(host, text)
    assert run.error is not None
    assert (run.error.line, run.error.column) == (1, 1)  # the statement's position
    assert "digital_" in str(run.error)
    assert host.arm.io.digital_out == 0


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("digital_in[1] = True", "digital_in[n] cannot be assigned"),
        ("x = digital_out", "compile_error_name_not_found:digital_out"),
        ("x = digital_out[1, 2]", "compile_error_name_not_found:digital_out"),
        ("digital_out[1][0] = True", "digital_out[n] cannot be assigned"),
        ("x = digital_inn[1]", "compile_error_name_not_found:digital_inn"),
    ],
)
def test_misuses_are_compile_errors(text: str, message: str) -> None:
    with pytest.raises(ScriptCompileError, match=message.replace("[", r"\[")):
        compile_program(text, series="cb3", version=(3, 15))


def test_a_program_variable_of_the_same_name_shadows_the_controllers() -> None:
    host = _host()
    text = (
        "def prog():\n"
        "  digital_out = [False, False, False]\n"
        "  digital_out[2] = True\n"
        "  write_output_boolean_register(0, digital_out[2])\n"
        "  def f(digital_in):\n"
        "    return digital_in[0]\n"
        "  end\n"
        "  write_output_integer_register(0, f([7]))\n"
        "end\n"
    )
    run = _run(host, text)
    assert run.error is None
    assert run.variable("digital_out") == [False, False, True]
    assert host.arm.io.digital_out == 0
    assert host.arm.io.registers_bit[0] is True
    assert host.arm.io.registers_int[0] == 7


def test_a_function_uses_the_controllers_variable_when_it_has_none_of_its_own() -> None:
    host = _host()
    text = "def prog():\n  def f():\n    digital_out[1] = True\n    return digital_out[1]\n  end\n"
    text += "  x = f()\nend\n"
    run = _run(host, text)
    assert run.error is None
    assert run.variable("x") is True
    assert host.arm.io.digital_out == 1 << 1
