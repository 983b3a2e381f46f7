"""Standard analog outputs: set as a level 0..1 of their domain, reported in amperes (4-20 mA) or volts
(0-10 V) by every interface that reads them back (UR's RTDE guide and script manual; docs/fake-robot.md,
"RTDE inputs, units and small fixes")."""

from __future__ import annotations

import pytest

from tests.fakeur.judges import fake_robot, wait_until
from tests.fakeur.test_controller_life import manual_fake
from tests.fakeur.test_controller_scripts import _eventually, _message, _primary, _send
from urdaemon.fakeur.reports import output_getter
from urdaemon.protocols import primary as prim

pytestmark = pytest.mark.timeout(120)

PROGRAM = """def units():
  set_analog_outputdomain(0, 1)
  set_standard_analog_out(0, 0.25)
  set_analog_outputdomain(1, 0)
  set_standard_analog_out(1, 0.5)
  write_output_float_register(0, get_standard_analog_out(0))
  write_output_float_register(1, get_analog_out(1))
  while True:
    sync()
  end
end
"""


async def test_a_script_sets_levels_and_every_interface_reads_amperes_or_volts() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        link = await _primary(controller)
        await _send(controller, 30002, PROGRAM)
        await _eventually(controller, lambda: controller.programs.name is not None)
        clock.turn(5)
        arm = controller.arm
        # the script reads back what it set, in its domain's unit: 0.25 of 0-10 V, 0.5 of 4-20 mA
        assert arm.io.registers_double[0] == pytest.approx(2.5)
        assert arm.io.registers_double[1] == pytest.approx(0.012)
        registers = controller.input_registers
        assert output_getter("standard_analog_output0", "DOUBLE", registers)(arm) == pytest.approx(2.5)
        assert output_getter("standard_analog_output1", "DOUBLE", registers)(arm) == pytest.approx(0.012)
        state = await _message(link, prim.RobotState, clock)
        board = state.get(prim.MasterboardData)
        assert board is not None
        assert (board.analog_output_domain0, board.analog_output_domain1) == (1, 0)
        assert board.analog_output0 == pytest.approx(2.5)
        assert board.analog_output1 == pytest.approx(0.012)
        link.close()


def test_ur_rtde_sets_a_voltage_and_a_current_ratio_and_reads_volts_and_amperes() -> None:
    """Reproduction: after setAnalogOutputVoltage(0, 0.5) ur_rtde read standard_analog_output0 as 0.5."""
    rtde_io = pytest.importorskip("rtde_io")
    rtde_receive = pytest.importorskip("rtde_receive")
    with fake_robot("ur10e", "--powered") as fake:
        io = rtde_io.RTDEIOInterface(fake.address)
        receiver = rtde_receive.RTDEReceiveInterface(fake.address)
        try:
            assert io.setAnalogOutputVoltage(0, 0.5)
            assert io.setAnalogOutputCurrent(1, 0.25)
            volts = wait_until(lambda: abs(receiver.getStandardAnalogOutput0() - 5.0) < 1e-9, 10.0)
            assert volts, receiver.getStandardAnalogOutput0()
            amperes = wait_until(lambda: abs(receiver.getStandardAnalogOutput1() - 0.008) < 1e-9, 10.0)
            assert amperes, receiver.getStandardAnalogOutput1()
        finally:
            io.disconnect()
            receiver.disconnect()
