"""read_port_*/write_port_*: the controller's Modbus map onto the fake arm's IO and state (lib_ports).

On f5f0e26 each of these builtins stopped the program with "not simulated"."""

from __future__ import annotations

import pytest

from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.urscript import compile_program
from urdaemon.fakeur.urscript import lib_ports as ports
from urdaemon.fakeur.urscript.lib_motion import tcp_pose
from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError
from urdaemon.fakeur.urscript.script_host import InputRegisters, ScriptHost
from urdaemon.model import RobotMode

DT = 0.002


def _host() -> ScriptHost:
    model = load_ur_model("ur10e")
    return ScriptHost(FakeArm(model, model.dh, powered=True), step_time=DT, version=(5, 15))


def test_output_bits_and_words_land_on_the_arms_outputs() -> None:
    host = _host()
    io = host.arm.io
    ports.write_port_bit(host, 16 + 3, True)  # standard output 3
    ports.write_port_bit(host, 16 + 9, True)  # tool output 1
    ports.write_port_bit(host, 136 + 2, True)  # configurable output 2
    assert io.digital_out == (1 << 3) | (1 << 17) | (1 << 10)
    assert ports.read_port_register(host, 1) == (1 << 3) | (1 << 9)
    assert ports.read_port_register(host, 22) == 0b10
    assert ports.read_port_register(host, 31) == 0b100
    ports.write_port_register(host, 3, 1 << 3)  # clear mask
    ports.write_port_bit(host, 32 + 5, True)  # set mask bit 5
    assert io.digital_out & 0xFF == 1 << 5
    ports.write_port_register(host, 33, 0b100)
    assert not io.digital_out >> 10 & 1
    ports.write_port_register(host, 22, 0b01)
    assert io.digital_out >> 16 & 0x3 == 0b01


def test_inputs_are_read_only_and_map_their_bits() -> None:
    host = _host()
    host.arm.io.digital_in = (1 << 2) | (1 << 9) | (1 << 16)
    assert ports.read_port_bit(host, 2) is True
    assert ports.read_port_bit(host, 8) is True  # tool input 0 is bit 8 of register 0
    assert ports.read_port_bit(host, 128 + 1) is True  # configurable input 1
    assert ports.read_port_register(host, 0) == (1 << 2) | (1 << 8)
    assert ports.read_port_register(host, 21) == 1
    with pytest.raises(ScriptRuntimeError, match="address 2 is not writable"):
        ports.write_port_bit(host, 2, True)
    with pytest.raises(ScriptRuntimeError, match="address 0 is not writable"):
        ports.write_port_register(host, 0, 1)


def test_analog_registers_in_milliunits_follow_the_domains() -> None:
    host = _host()
    io = host.arm.io
    ports.write_port_register(host, 17, 1)  # analog output 0 in voltage mode
    ports.write_port_register(host, 16, 2500)  # 2.5 V
    assert io.analog_out[0] == pytest.approx(0.25)
    assert io.analog_out_types == 1 << 2
    io.analog_out[1] = 0.5  # output 1 in current mode: 4..20 mA
    assert ports.read_port_register(host, 18) == 12
    with pytest.raises(ScriptRuntimeError, match="outside"):
        ports.write_port_register(host, 18, 2)
    io.analog_in[1] = 3.2
    assert ports.read_port_register(host, 6) == 3200
    ports.write_port_register(host, 20, 24)
    assert io.tool_voltage == 24


def test_general_purpose_registers_and_boolean_registers() -> None:
    host = _host()
    ports.write_port_register(host, 130, 65535)  # read back signed, as the manual says
    assert ports.read_port_register(host, 130) == -1
    ports.write_port_register(host, 131, -2)
    assert ports.read_port_register(host, 131) == -2
    ports.write_port_register(host, 132, 1234)
    assert ports.read_port_register(host, 132) == 1234
    assert ports.read_port_register(host, 133) == 0
    for bad in (65536, -32769, 1.5, True):
        with pytest.raises(ScriptRuntimeError, match="16-bit"):
            ports.write_port_register(host, 130, bad)
    ports.write_port_bit(host, 500 + 70, True)
    assert host.arm.io.registers_bit[70] is True
    registers = InputRegisters(bits={5: True})
    model = load_ur_model("ur10e")
    other = ScriptHost(FakeArm(model, model.dh), step_time=DT, input_registers=registers)
    assert ports.read_port_bit(other, 300 + 5) is True


def test_state_registers_report_the_arm() -> None:
    host = _host()
    arm = host.arm
    assert ports.read_port_register(host, 256) == 5
    assert ports.read_port_register(host, 257) == 15
    assert ports.read_port_register(host, 258) == int(RobotMode.RUNNING)
    assert ports.read_port_register(host, 260) == 1
    arm.q = [0.5, -1.2, 1.4, -1.6, -1.5, 0.2]
    for i in range(6):
        assert ports.read_port_register(host, 270 + i) == round(arm.q[i] * 1000)
    x = ports.read_port_register(host, 400)
    assert x == round(tcp_pose(arm, arm.q)[0] * 10000)
    assert -32768 <= x <= 32767


@pytest.mark.parametrize("address", [24, 34, 127, 259, 1000])
def test_addresses_off_the_map_are_runtime_errors(address: int) -> None:
    host = _host()
    with pytest.raises(ScriptRuntimeError, match=f"address {address} is not readable"):
        ports.read_port_register(host, address)


def test_a_script_reads_back_what_it_wrote() -> None:
    host = _host()
    run = compile_program(
        "write_port_register(200, 1234)\nglobal r = read_port_register(200)\n"
        "write_port_bit(20, True)\nglobal b = read_port_bit(20)\n",
        series="e",
        version=(5, 15),
    ).start(host)
    run.step()
    assert run.done
    assert run.error is None
    assert run.variable("r") == 1234
    assert run.variable("b") is True
    assert host.arm.io.digital_out == 1 << 4
