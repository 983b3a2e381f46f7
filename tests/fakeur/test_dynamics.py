"""The fake's kinematics and dynamics builtins (PolyScope 5.23+) and direct torque control, run as
URScript on a fake arm cycle by cycle.

Reproduction on the code before issue 33: every builtin here stopped the program with "not simulated
by the fake controller", and get_joint_torques was always zero.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.fakeur.urscript.library_host import DT, make_host, run_script
from urdaemon.fakeur.fake_arm import arm_payload, joint_torques
from urdaemon.fakeur.urscript import compile_program
from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError
from urdaemon.fakeur.urscript.script_host import ScriptHost

VERSION = (5, 25)
"""A controller that has direct_torque's friction scales (5.25) and the dynamics getters (5.23)."""
START = [0.3, -1.2, 1.4, -1.6, -1.5, 0.2]


def _host() -> ScriptHost:
    host = make_host("ur10e", playing=True, version=VERSION)
    host.arm.q[:] = START
    host.arm.history.record(START)
    return host


def test_the_getters_return_the_models_matrices_as_rows() -> None:
    host = _host()
    arm = host.arm
    arm.payload_mass, arm.payload_cog = 2.0, [0.0, 0.01, 0.05]
    text = """def p():
  global m = get_mass_matrix()
  global j = get_jacobian()
  global jd = get_jacobian_time_derivative(qd=[0.1, 0.2, -0.3, 0.4, 0.5, -0.6])
  global c = get_coriolis_and_centrifugal_torques(qd=[0.1, 0.2, -0.3, 0.4, 0.5, -0.6])
  global t = get_joint_torques()
  global m01 = m[0, 1]
end
"""
    run = run_script(host, text)
    assert run.error is None
    values = {name: run.variable(name) for name in ("m", "m01", "j", "jd", "c", "t")}
    qd = [0.1, 0.2, -0.3, 0.4, 0.5, -0.6]
    dynamics, payload = arm.drive.dynamics, arm_payload(arm)
    assert values["m"] == dynamics.mass_matrix(START, payload)
    assert values["m01"] == values["m"][0][1]
    assert values["j"] == dynamics.jacobian(START)
    assert values["jd"] == dynamics.jacobian_derivative(START, qd)
    assert values["c"] == dynamics.coriolis(START, qd, payload)
    assert values["t"] == [0.0] * 6, "free air: nothing beyond the arm's own motion"


def test_rotor_inertia_is_refused_as_not_published() -> None:
    host = _host()
    run = run_script(host, "def p():\n  m = get_mass_matrix(include_rotors_inertia=True)\nend\n")
    assert isinstance(run.error, ScriptRuntimeError)
    assert "rotor" in str(run.error)


def test_direct_torque_of_zero_holds_the_arm_against_gravity() -> None:
    """The manual: direct_torque always compensates gravity, so a zero command holds the arm where it is;
    the torques the joints exert meanwhile are the gravity torques."""
    host = _host()
    arm = host.arm
    text = (
        "def p():\n  i = 0\n  while i < 200:\n"
        "    direct_torque([0, 0, 0, 0, 0, 0])\n    i = i + 1\n  end\nend\n"
    )
    run = run_script(host, text, cycles=400)
    assert run.error is None
    assert arm.q == pytest.approx(START, abs=1e-12)
    hold = arm.drive.dynamics.gravity_torques(START, arm.gravity, arm_payload(arm))
    assert joint_torques(arm) == pytest.approx(hold, abs=1e-9)
    assert max(abs(v) for v in hold) > 10.0, "the shoulder and elbow hold the arm up"


def test_direct_torque_moves_the_arm_by_its_dynamics_and_stops_when_not_renewed() -> None:
    host = _host()
    arm = host.arm
    torque = [0.0, 0.0, 0.0, 0.0, 0.0, 0.5]
    expected = arm.drive.dynamics.forward_dynamics(
        START,
        [0.0] * 6,
        [t + g for t, g in zip(torque, arm.drive.dynamics.gravity_torques(START, arm.gravity), strict=True)],
        arm.gravity,
    )
    text = "def p():\n  direct_torque([0, 0, 0, 0, 0, 0.5], friction_comp=False)\nend\n"
    run = compile_program(text, series="e", version=VERSION).start(host)
    run.step()  # the call: this cycle's torque
    arm.step(DT)
    assert run.error is None
    assert arm.qdd == pytest.approx(expected, rel=1e-9, abs=1e-12)
    assert arm.qd[5] == pytest.approx(expected[5] * DT, rel=1e-9)
    assert arm.qd[5] > 0.0
    run.step()  # the call returns, the program ends
    assert run.done
    for _ in range(200):  # no new call: back to position control, the arm comes to rest
        arm.step(DT)
    assert arm.qd == [0.0] * 6
    assert arm.steady


def test_direct_torque_checks_its_friction_scales() -> None:
    host = _host()
    text = "def p():\n  direct_torque([0, 0, 0, 0, 0, 0], viscous_scale=[2, 0, 0, 0, 0, 0])\nend\n"
    run = run_script(host, text)
    assert "viscous_scale" in str(run.error)


def test_get_joint_torques_are_those_of_the_wrench_the_tool_feels() -> None:
    host = _host()
    arm = host.arm
    arm.tcp_force = [0.0, 0.0, -20.0, 0.0, 0.0, 0.0]
    run = run_script(host, "def p():\n  global t = get_joint_torques()\nend\n")
    expected = np.array(arm.drive.dynamics.jacobian(arm.q, arm.tcp_offset)).T @ np.array(arm.tcp_force)
    assert run.error is None
    assert run.variable("t") == pytest.approx(list(expected), abs=1e-12)
