"""Facts defined once (issue 15): every user of a fact takes it from the one place that defines it.

Reproduction: each fact below was written out again by its users (the fake's ``RuntimeState``, the
links' and the fake's port numbers, ``UR_IO_SIZES``, the speedj acceleration in the template, the
joint counts, the dashboard's refusal prefixes); on that code these names do not exist or are not
the same object, so every test here fails.
"""

from __future__ import annotations

import re

import pytest

from urdaemon import model, urscript
from urdaemon.protocols import (
    dashboard,
    kinematics_hash,
    primary,
    realtime,
    reverse,
    rtde,
    rtde_variables,
    script_command,
    script_sender,
    trajectory_point,
)


def test_the_run_states_and_status_bits_are_rtde_variables() -> None:
    from urdaemon.backends.ur import reverse_channel, rtde_link
    from urdaemon.fakeur import fake_arm, life

    states = rtde_variables.RuntimeState
    assert life.RuntimeState is states
    assert fake_arm.RuntimeState is states
    assert (reverse_channel.RUNTIME_PLAYING, reverse_channel.RUNTIME_PAUSING) == (
        states.PLAYING,
        states.PAUSING,
    )
    assert (rtde_link.RUNTIME_PAUSED, rtde_link.RUNTIME_RESUMING) == (states.PAUSED, states.RESUMING)
    assert rtde_variables.POWER_ON_BIT | rtde_variables.PROGRAM_RUNNING_BIT == 0b11


def test_every_port_is_its_protocol_modules() -> None:
    from urdaemon.backends.ur import dashboard_link, primary_link, rtde_link
    from urdaemon.fakeur.controller import FakePorts

    robot = (dashboard.DASHBOARD_PORT, primary.PRIMARY_PORT, primary.SECONDARY_PORT, realtime.REALTIME_PORT)
    assert FakePorts() == FakePorts(*robot, rtde.RTDE_PORT)
    assert (dashboard_link.DASHBOARD_PORT, primary_link.PRIMARY_PORT, rtde_link.RTDE_PORT) == (
        dashboard.DASHBOARD_PORT,
        primary.PRIMARY_PORT,
        rtde.RTDE_PORT,
    )
    callbacks = (reverse.REVERSE_PORT, trajectory_point.TRAJECTORY_PORT, script_command.SCRIPT_COMMAND_PORT)
    assert callbacks == (
        urscript.DEFAULT_REVERSE_PORT,
        urscript.DEFAULT_TRAJECTORY_PORT,
        urscript.DEFAULT_SCRIPT_COMMAND_PORT,
    )
    assert script_sender.SCRIPT_SENDER_PORT == reverse.REVERSE_PORT + 1


def test_the_io_layout_and_voltages_are_model_pys() -> None:
    from urdaemon.backends.ur import robot_commands as services
    from urdaemon.fakeur.urscript import lib_io

    assert services.UR_IO_SIZES is model.IO_SIZES
    assert lib_io.TOOL_VOLTAGES is model.TOOL_VOLTAGES is script_command.TOOL_VOLTAGES
    assert (model.STANDARD_IO_SHIFT, model.CONFIGURABLE_IO_SHIFT, model.TOOL_IO_SHIFT) == (0, 8, 16)


@pytest.mark.parametrize("bit", range(18))
def test_the_daemon_splits_rtdes_io_bits_as_the_layout_says(bit: int) -> None:
    from urdaemon.backends.ur.rtde_link import StateMapper

    names = ("timestamp", "actual_q", "actual_qd", "actual_digital_output_bits")
    state = model.RobotState.zeros(model.UR_JOINTS)
    StateMapper(names).apply((0.0, [0.0] * 6, [0.0] * 6, 1 << bit), state)
    lists = (
        (model.STANDARD_IO_SHIFT, state.digital_out),
        (model.CONFIGURABLE_IO_SHIFT, state.configurable_out),
        (model.TOOL_IO_SHIFT, state.tool_out),
    )
    set_pins = [(shift, pin) for shift, pins in lists for pin, on in enumerate(pins) if on]
    assert [shift + pin for shift, pin in set_pins] == [bit]


def test_the_speedj_acceleration_is_rendered_from_urscript_py() -> None:
    text = urscript.render_control_script(urscript.ScriptParameters("127.0.0.1"))
    rendered = re.findall(r"^UD_SPEEDJ_ACCEL = (\S+)$", text, re.MULTILINE)
    assert rendered == [repr(urscript.SPEEDJ_ACCELERATION)]


def test_the_joint_count_is_model_pys() -> None:
    from urdaemon.fakeur import joint_motion as motion

    assert len(model.UR_JOINTS) == model.UR_JOINT_COUNT
    assert reverse.JOINTS == trajectory_point.JOINTS == kinematics_hash.DH_JOINT_COUNT == motion.JOINTS


def test_a_refused_dashboard_line_is_read_by_one_rule() -> None:
    assert dashboard.is_refusal(dashboard.unknown_command_text("frobnicate"))
    assert dashboard.is_refusal("Failed to execute: play")
    assert dashboard.is_refusal("")
    assert not dashboard.is_refusal("Powering on")
