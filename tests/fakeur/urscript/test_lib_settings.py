"""Controller settings a program changes for later, and powerdown (lib_settings)."""

from __future__ import annotations

import re

import pytest

from tests.fakeur.urscript.library_host import DT, make_host, run_script
from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.urscript.lib_settings import pause_on_error_of, settings_of
from urdaemon.fakeur.urscript.script_host import ScriptHost
from urdaemon.model import RobotMode
from urdaemon.protocols.rtde_variables import RuntimeState


def _host() -> ScriptHost:
    """A UR5e on a 5.17 controller, its program playing."""
    return make_host("ur5e", playing=True, version=(5, 17))


def test_settings_are_recorded_for_later_programs() -> None:
    """On f5f0e26 each of these stopped the program with "not simulated"."""
    host = _host()
    run = run_script(
        host,
        "set_base_acceleration([0.1, 0, -0.2])\n"
        "set_safety_mode_transition_hardness(1)\n"
        "pause_on_error_code(173, 2)\n"
        "position_deviation_warning(True, 0.5)\n"
        "high_holding_torque_disable()\n"
        "set_baselight_solid(255, 128, 0)\n",
        cycles=20,
    )
    assert run.error is None
    settings = settings_of(host.arm)
    assert settings.base_acceleration == [0.1, 0.0, -0.2]
    assert settings.safety_transition_hardness == 1
    assert pause_on_error_of(host) == {(173, 2)}
    assert settings.deviation_warning == (True, 0.5)
    assert settings.high_holding_torque is False
    assert settings.baselight == ("solid", (255.0, 128.0, 0.0))
    later = run_script(host, "global a = get_base_acceleration()\nset_baselight_iec()\n", cycles=20)
    assert later.variable("a") == [0.1, 0.0, -0.2]
    assert settings.baselight[0] == "iec"
    assert pause_on_error_of(host) == {(173, 2)}, "the same program's host"
    hard = run_script(host, "set_safety_mode_transition_hardness(0)\n", cycles=20)
    assert hard.error is not None
    assert "not simulated" in hard.error.message, "the fake's stops are soft: a hard one is not faked"
    fresh = ScriptHost(host.arm, step_time=DT)
    assert pause_on_error_of(fresh) == set(), "the manual resets it when the program stops"
    other = load_ur_model("ur5e")
    assert settings_of(FakeArm(other, other.dh)).base_acceleration == [0.0, 0.0, 0.0], "per robot"


@pytest.mark.parametrize(
    ("line", "words"),
    [
        ("set_base_acceleration([1, 2])", "expected \\[x, y, z\\]"),
        ("set_safety_mode_transition_hardness(2)", "0 or 1"),
        ("position_deviation_warning(True, 1.5)", "threshold"),
        ("set_baselight_solid(300, 0, 0)", "0..255"),
        ('pause_on_error_code("C173", 0)', "integer"),
    ],
)
def test_bad_settings_are_runtime_errors(line: str, words: str) -> None:
    run = run_script(_host(), line + "\n", cycles=20)
    error = run.error
    assert error is not None
    assert error.line == 1
    assert re.search(words, error.message), error.message


def test_powerdown_powers_the_arm_off_and_ends_the_program() -> None:
    """As URSim: the arm is POWER_OFF, the program stops at once (the line after it never runs)."""
    host = _host()
    run = run_script(host, "global before = 1\npowerdown()\nglobal after = 2\n", cycles=3)
    assert run.error is None
    assert host.arm.robot_mode is RobotMode.POWER_OFF
    assert host.arm.runtime_state is RuntimeState.STOPPED
    assert run.variable("before") == 1
    with pytest.raises(KeyError):
        run.variable("after")


async def test_powerdown_on_the_controller_stops_the_program_and_powers_off() -> None:
    """End to end on a fake controller whose clock the test turns: the program sent on the primary
    interface starts, calls powerdown, and the controller reports it stopped with the arm POWER_OFF.
    On f5f0e26 powerdown stopped the program with "not simulated" and the arm stayed RUNNING."""
    from tests.fakeur.test_controller import Link
    from tests.fakeur.test_controller_life import manual_fake
    from urdaemon.protocols import primary as prim
    from urdaemon.protocols._buffer import Side

    async with manual_fake(powered=True) as (controller, clock):
        link = await Link.open(prim.PrimaryConnection(Side.DAEMON), controller.address, 30001)
        await link.next(prim.VersionMessage)
        link.writer.write(b'def shutdown():\n  sync()\n  powerdown()\n  textmsg("still here")\nend\n')
        started = await link.next(prim.KeyMessage)
        assert (started.title, started.text) == ("PROGRAM_XXX_STARTED", "shutdown")
        clock.until(lambda: controller.programs.main is None, limit=50)
        stopped = await link.next(prim.KeyMessage)
        assert (stopped.title, stopped.text) == ("PROGRAM_XXX_STOPPED", "shutdown")
        assert controller.arm.robot_mode is RobotMode.POWER_OFF
        assert controller.arm.runtime_state is RuntimeState.STOPPED
        link.close()


async def test_run_state_outputs_apply_when_the_controller_starts_and_stops_a_program() -> None:
    """A program asks standard output 3 to be high while a program runs and low when none does: the
    controller applies it as the next program starts and as that one ends (before 2c358bb the choice was
    only recorded)."""
    from tests.fakeur.test_controller import Link
    from tests.fakeur.test_controller_life import manual_fake
    from urdaemon.protocols import primary as prim
    from urdaemon.protocols._buffer import Side

    bit = 1 << 3
    async with manual_fake(powered=True) as (controller, clock):
        link = await Link.open(prim.PrimaryConnection(Side.DAEMON), controller.address, 30001)
        await link.next(prim.VersionMessage)
        link.writer.write(b"def choose():\n  set_runstate_standard_digital_output_to_value(3, 3)\nend\n")
        assert (await link.next(prim.KeyMessage)).title == "PROGRAM_XXX_STARTED"
        clock.until(lambda: controller.programs.main is None, limit=50)
        assert (await link.next(prim.KeyMessage)).title == "PROGRAM_XXX_STOPPED"
        assert not controller.arm.io.digital_out & bit, "stopped: low"
        link.writer.write(b"def wait():\n  while True:\n    sync()\n  end\nend\n")
        assert (await link.next(prim.KeyMessage)).title == "PROGRAM_XXX_STARTED"
        assert controller.arm.io.digital_out & bit, "running: high"
        controller.programs.stop()
        assert not controller.arm.io.digital_out & bit, "stopped again: low"
        link.close()
