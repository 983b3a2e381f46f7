"""Payload, TCP, gravity, force mode, freedrive, tool contact and watchdog builtins."""

from __future__ import annotations

from typing import Any

import pytest

from tests.fakeur.urscript.library_host import DT, make_host, run_script
from urdaemon.fakeur.urscript import lib_config as cfg
from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError, UrPose
from urdaemon.fakeur.urscript.script_host import Watchdog
from urdaemon.fakeur.urscript.signatures import ACTIVE_TCP


def test_payload_setters_and_getters() -> None:
    host = make_host()
    cfg.set_target_payload(host, 2.5, [0.0, 0.01, 0.05], [0.1, 0.2, 0.3, 0, 0, 0], 0)
    arm = host.arm
    assert (arm.payload_mass, arm.payload_cog, arm.payload_inertia) == (
        2.5,
        [0.0, 0.01, 0.05],
        [0.1, 0.2, 0.3, 0, 0, 0],
    )
    assert cfg.get_target_payload(host) == 2.5
    assert cfg.get_target_payload_cog(host) == [0.0, 0.01, 0.05]
    assert cfg.get_target_payload_inertia(host) == [0.1, 0.2, 0.3, 0.0, 0.0, 0.0]
    cfg.set_payload_mass(host, 1.0)
    cfg.set_payload_cog(host, [0, 0, 0.1])
    assert (arm.payload_mass, arm.payload_cog) == (1.0, [0.0, 0.0, 0.1])


def test_set_payload_without_cog_uses_the_tcp_position() -> None:
    host = make_host()
    cfg.set_tcp(host, [0, 0, 0.2, 0, 0, 0])
    cfg.set_payload(host, 3.0, ACTIVE_TCP)
    assert host.arm.payload_mass == 3.0
    assert host.arm.payload_cog == [0.0, 0.0, 0.2]


def test_tcp_and_gravity() -> None:
    host = make_host()
    cfg.set_tcp(host, UrPose([0.0, 0.0, 0.1, 0.0, 0.0, 1.0]))
    offset = cfg.get_tcp_offset(host)
    assert isinstance(offset, UrPose)
    assert offset == [0.0, 0.0, 0.1, 0.0, 0.0, 1.0]
    cfg.set_gravity(host, [0, 9.82, 0])
    assert host.arm.gravity == [0.0, 9.82, 0.0]
    assert cfg.get_gravity(host) == [0.0, 9.82, 0.0]


@pytest.mark.parametrize(
    ("call", "args"),
    [
        (cfg.set_payload, (-1.0, [0, 0, 0])),
        (cfg.set_target_payload, (1.0, [0, 0])),
        (cfg.set_tcp, ([0, 0, 0.1],)),
        (cfg.set_gravity, ("down",)),
        (cfg.force_mode, ([0] * 6, [0, 0, 2, 0, 0, 0], [0] * 6, 2, [0.1] * 6)),
        (cfg.force_mode, ([0] * 6, [0, 0, 1, 0, 0, 0], [0] * 6, 4, [0.1] * 6)),
        (cfg.force_mode_set_damping, (1.5,)),
        (cfg.force_mode_set_gain_scaling, (-0.1,)),
        (cfg.set_tool_communication, (True, 4800, 0, 1, 1.5, 3.5)),
        (cfg.set_tool_communication, (True, 115200, 3, 1, 1.5, 3.5)),
        (cfg.set_tool_communication, (1, 115200, 0, 1, 1.5, 3.5)),
        (cfg.set_tool_digital_output_mode, (2, 1)),
        (cfg.set_tool_digital_output_mode, (0, 4)),
        (cfg.set_tool_output_mode, (2,)),
        (cfg.rtde_set_watchdog, ("output_int_register_0", 10, "stop")),
        (cfg.rtde_set_watchdog, ("input_int_register_0", 0, "stop")),
        (cfg.rtde_set_watchdog, ("input_int_register_0", 10, "halt")),
    ],
)
def test_bad_arguments_are_runtime_errors(call: Any, args: tuple[Any, ...]) -> None:
    with pytest.raises(ScriptRuntimeError, match=call.__name__):
        call(make_host(), *args)


def test_force_mode_on_and_off_with_its_parameters() -> None:
    host = make_host()
    cfg.force_mode_set_damping(host, 0.025)
    cfg.force_mode_set_gain_scaling(host, 0.5)
    cfg.force_mode(host, UrPose([0.0] * 6), [0, 0, 1, 0, 0, 0], [0, 0, -5, 0, 0, 0], 2, [0.1] * 6)
    assert host.arm.force_mode is True
    assert host.config.force_wrench == [0.0, 0.0, -5.0, 0.0, 0.0, 0.0]
    assert (cfg.force_mode_get_damping(host), cfg.force_mode_get_gain_scaling(host)) == (0.025, 0.5)
    cfg.zero_ftsensor(host)
    assert host.config.ft_zeroed_at == host.now
    cfg.end_force_mode(host)
    assert host.arm.force_mode is False


def test_freedrive_teach_mode_and_tool_contact() -> None:
    host = make_host()
    seen = []
    cfg.freedrive_mode(host, [1, 1, 1, 0, 0, 0], UrPose([0.0] * 6))
    seen.append(host.arm.freedrive)
    assert host.config.free_axes == [1, 1, 1, 0, 0, 0]
    assert cfg.get_freedrive_status(host) == 0
    cfg.end_freedrive_mode(host)
    seen.append(host.arm.freedrive)
    cfg.teach_mode(host)
    seen.append(host.arm.freedrive)
    cfg.end_teach_mode(host)
    seen.append(host.arm.freedrive)
    assert seen == [True, False, True, False]
    assert cfg.tool_contact(host, [0, 0, -0.1, 0, 0, 0]) == 0


def test_tool_io_configuration_is_recorded() -> None:
    host = make_host()
    cfg.set_tool_communication(host, True, 115200, 0, 1, 1.5, 3.5)
    cfg.set_tool_digital_output_mode(host, 1, 3)
    cfg.set_tool_output_mode(host, 1)
    assert host.config.tool_communication == (True, 115200, 0, 1, 1.5, 3.5)
    assert host.config.tool_output_modes == [2, 3]
    assert host.config.tool_output_mode == 1


def test_watchdog_is_recorded_for_the_controller_and_dropped_at_close() -> None:
    host = make_host()
    host.arm.step(0.5)
    cfg.rtde_set_watchdog(host, "input_int_register_0", 10, "stop")
    cfg.rtde_set_watchdog(host, "input_double_register_1", 2.5, "pause")
    cfg.rtde_set_watchdog(host, "input_int_register_0", 20, "ignore")
    assert host.watchdogs == {
        "input_int_register_0": Watchdog("input_int_register_0", 20.0, "ignore", 0.5),
        "input_double_register_1": Watchdog("input_double_register_1", 2.5, "pause", 0.5),
    }
    host.close()
    assert host.watchdogs == {}


def test_watchdog_actions_are_named_in_any_case() -> None:
    """Reproduction: UR's RTDE example program (rtde_control_loop.urp) calls
    ``rtde_set_watchdog("input_int_register_0", 1, "PAUSE")``, which the fake refused."""
    host = make_host()
    cfg.rtde_set_watchdog(host, "input_int_register_0", 1, "PAUSE")
    cfg.rtde_set_watchdog(host, "input_int_register_1", 1, "Stop")
    assert host.watchdogs["input_int_register_0"].action == "pause"
    assert host.watchdogs["input_int_register_1"].action == "stop"


def test_a_script_configures_the_arm() -> None:
    """ur_rtde's and our control script's calls, in their keyword forms."""
    host = make_host()
    error = run_script(
        host,
        "set_tcp(p[0, 0, 0.15, 0, 0, 0])\n"
        "set_target_payload(1.2, [0, 0, 0.05])\n"
        "set_payload(1.4)\n"
        "set_gravity([0, 0, 9.82])\n"
        "force_mode_set_damping(0.1)\n"
        "force_mode(p[0, 0, 0, 0, 0, 0], [0, 0, 1, 0, 0, 0], [0, 0, 10, 0, 0, 0], 2,"
        " [0.1, 0.1, 0.1, 0.1, 0.1, 0.1])\n"
        "end_force_mode()\n"
        "freedrive_mode(freeAxes=[1, 0, 0, 0, 0, 1])\n"
        'rtde_set_watchdog("input_int_register_24", 10, "stop")\n'
        "if tool_contact(direction=[0, 0, -0.1, 0, 0, 0]) != 0:\n  halt\nend\n"
        "write_output_integer_register(0, get_freedrive_status())\n",
    ).error
    assert error is None
    arm = host.arm
    assert arm.tcp_offset == [0.0, 0.0, 0.15, 0.0, 0.0, 0.0]
    assert (arm.payload_mass, arm.payload_cog) == (1.4, [0.0, 0.0, 0.15])
    assert arm.force_mode is False
    assert arm.freedrive is True
    assert host.config.free_axes == [1, 0, 0, 0, 0, 1]
    assert set(host.watchdogs) == {"input_int_register_24"}


def test_an_external_ft_sensor_is_recorded_while_enabled_and_bad_arguments_are_errors() -> None:
    """urcl's external F/T example calls ft_rtde_input_enable first: it runs, and a disable forgets it."""
    host = make_host()
    cfg.ft_rtde_input_enable(host, True, 0.5, [0.0, 0.0, 0.02], [0.0, 0.0, 0.01])
    assert cfg._config(host).external_ft_sensor == (0.5, [0.0, 0.0, 0.02], [0.0, 0.0, 0.01])
    cfg.enable_external_ft_sensor(host, False, 0.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    assert cfg._config(host).external_ft_sensor is None
    with pytest.raises(ScriptRuntimeError, match="sensor_mass"):
        cfg.ft_rtde_input_enable(host, True, -1.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    with pytest.raises(ScriptRuntimeError, match="enable"):
        cfg.ft_rtde_input_enable(host, 1, 0.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])


def test_freedrive_free_axes_are_in_the_feature_frame_and_force_mode_settings_reach_the_model() -> None:
    """``freedrive_mode``'s feature turns its free axes; damping and gain scaling set during force mode
    reach the contact model (fakeur/contact.py). At f5f0e26 freedrive and force mode moved nothing."""
    import math

    from urdaemon.fakeur.contact import surroundings_of

    host = make_host()
    arm = host.arm
    surroundings = surroundings_of(arm)
    turned = UrPose([0.0, 0.0, 0.0, 0.0, 0.0, math.pi / 2])  # its x is the base's y
    cfg.freedrive_mode(host, [1, 0, 0, 0, 0, 0], turned)
    surroundings.push[:] = [10.0, 0.0, 0.0, 0.0, 0.0, 0.0]  # along base x: not free
    start = arm.actual_tcp_pose()
    arm.step(DT)
    assert arm.actual_tcp_pose()[:3] == pytest.approx(start[:3], abs=1e-9)
    surroundings.push[:] = [0.0, 10.0, 0.0, 0.0, 0.0, 0.0]  # along base y: the feature's free x
    for _ in range(10):
        arm.step(DT)
    moved = [a - b for a, b in zip(arm.actual_tcp_pose()[:3], start[:3], strict=True)]
    assert moved[1] == pytest.approx(10 * DT * 10.0 * 0.005, rel=0.05)
    assert abs(moved[0]) < 1e-6
    cfg.end_freedrive_mode(host)
    cfg.force_mode(host, UrPose([0.0] * 6), [0, 0, 1, 0, 0, 0], [0, 0, -5, 0, 0, 0], 2, [0.1] * 6)
    cfg.force_mode_set_damping(host, 0.5)
    cfg.force_mode_set_gain_scaling(host, 1.5)
    settings = surroundings.force
    assert settings is not None
    assert (settings.damping, settings.gain_scaling) == (0.5, 1.5)
