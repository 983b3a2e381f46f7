"""URScript state getters and kinematics builtins read from the fake arm."""

from __future__ import annotations

import math
from collections.abc import Generator
from typing import Any

import pytest

from urdaemon.description import frames
from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.fake_arm import HISTORY_STEPS, FakeArm
from urdaemon.fakeur.urscript import lib_motion, lib_state
from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError, UrList, UrPose
from urdaemon.fakeur.urscript.script_host import ScriptHost
from urdaemon.fakeur.urscript.signatures import ACTIVE_TCP, CURRENT_JOINT_POSITIONS

DT = 0.002
TOOL = [0.01, -0.02, 0.15, 0.0, 0.0, 0.3]


def _host() -> ScriptHost:
    model = load_ur_model("ur5e")
    arm = FakeArm(model, model.dh, powered=True, initial_positions=[0.3, -1.2, 1.4, -1.6, -1.5, 0.2])
    arm.start_program()
    return ScriptHost(arm, step_time=DT)


def _cycles(host: ScriptHost, gen: Generator[None, None, Any], count: int) -> None:
    for _ in range(count):
        next(gen)
        host.arm.step(DT)


def test_joint_getters_read_actual_and_target_state_during_a_move() -> None:
    host = _host()
    arm = host.arm
    assert lib_state.get_actual_joint_positions(host) == arm.q
    assert isinstance(lib_state.get_actual_joint_positions(host), UrList)
    assert lib_state.get_actual_joint_speeds(host) == [0.0] * 6
    assert lib_state.is_steady(host)
    target = list(arm.q)
    target[0] += 0.5
    gen = lib_motion.movej(host, target, 1.4, 1.05, 0, 0)
    _cycles(host, gen, 50)
    speeds = lib_state.get_target_joint_speeds(host)
    assert speeds[0] == pytest.approx(1.4 * 50 * DT, rel=1e-6), "the trapezoid's ramp after 0.1 s"
    assert lib_state.get_actual_joint_speeds(host)[0] == pytest.approx(speeds[0], abs=1.4 * DT)
    assert lib_state.get_target_joint_positions(host) == pytest.approx(arm.q, abs=1e-12)
    assert lib_state.get_joint_positions(host) == lib_state.get_target_joint_positions(host)
    assert not lib_state.is_steady(host)
    waypoint = lib_state.get_target_waypoint(host)
    assert isinstance(waypoint, UrPose)
    assert list(waypoint) == pytest.approx(lib_motion.tcp_pose(arm, target), abs=1e-9)


def test_tcp_pose_applies_the_tcp_offset_to_the_flange() -> None:
    host = _host()
    arm = host.arm
    flange = lib_state.get_actual_tool_flange_pose(host)
    assert list(flange) == pytest.approx(arm.tcp_pose(), abs=1e-12)
    arm.tcp_offset = list(TOOL)
    tcp = lib_state.get_actual_tcp_pose(host)
    # the TCP point is the flange point plus the flange's rotation applied to the offset
    rotation = frames.frame_of_pose(flange)
    expected = [flange[i] + sum(rotation[3 * i + k] * TOOL[k] for k in range(3)) for i in range(3)]
    assert list(tcp[:3]) == pytest.approx(expected, abs=1e-12)
    assert list(lib_state.get_target_tcp_pose(host)) == pytest.approx(list(tcp), abs=1e-12)
    assert list(lib_state.get_forward_kin(host, CURRENT_JOINT_POSITIONS, ACTIVE_TCP)) == pytest.approx(
        list(tcp)
    )
    bare = lib_state.get_forward_kin(host, arm.q, [0.0] * 6)
    assert list(bare) == pytest.approx(list(flange), abs=1e-12)


def test_inverse_kin_round_trips_and_reports_unreachable_poses() -> None:
    host = _host()
    arm = host.arm
    arm.tcp_offset = list(TOOL)
    wanted = [0.5, -1.0, 1.1, -1.2, -1.4, 0.6]
    pose = lib_state.get_forward_kin(host, wanted, ACTIVE_TCP)
    q = lib_state.get_inverse_kin(host, pose, wanted, 1e-10, 1e-10, ACTIVE_TCP)
    assert list(q) == pytest.approx(wanted, abs=1e-8)
    assert lib_state.get_inverse_kin_has_solution(
        host, pose, CURRENT_JOINT_POSITIONS, 1e-10, 1e-10, ACTIVE_TCP
    )
    far = UrPose([3.0, 0.0, 0.5, 0.0, math.pi, 0.0])
    assert not lib_state.get_inverse_kin_has_solution(
        host, far, CURRENT_JOINT_POSITIONS, 1e-10, 1e-10, ACTIVE_TCP
    )
    with pytest.raises(ScriptRuntimeError, match="get_inverse_kin"):
        lib_state.get_inverse_kin(host, far, CURRENT_JOINT_POSITIONS, 1e-10, 1e-10, ACTIVE_TCP)
    assert lib_state.is_within_safety_limits(host, pose)
    assert not lib_state.is_within_safety_limits(host, far)


def test_tcp_speed_is_the_rate_of_the_tcp_pose() -> None:
    host = _host()
    arm = host.arm
    arm.tcp_offset = list(TOOL)
    gen = lib_motion.speedj(host, [0.2, -0.1, 0.15, 0.0, 0.3, -0.2], 4.0, 1.0)
    _cycles(host, gen, 60)
    speed = lib_state.get_target_tcp_speed(host)
    before = lib_state.get_actual_tcp_pose(host)
    next(gen, None)
    arm.step(DT)
    after = lib_state.get_actual_tcp_pose(host)
    linear = [(b - a) / DT for a, b in zip(before[:3], after[:3], strict=True)]
    assert list(speed[:3]) == pytest.approx(linear, abs=2e-3)
    turn = frames.pose_of_frame(
        frames.compose(frames.frame_of_pose(after), frames.inverse(frames.frame_of_pose(before)))
    )
    assert list(speed[3:]) == pytest.approx([v / DT for v in turn[3:]], abs=2e-3)
    assert list(lib_state.get_actual_tcp_speed(host)) == pytest.approx(list(speed), abs=2e-3)


def test_history_goes_back_cycle_by_cycle() -> None:
    host = _host()
    arm = host.arm
    seen = [list(arm.q)]
    gen = lib_motion.speedj(host, [0.3, 0, 0, 0, 0, 0], 10.0, 0.5)
    for _ in range(20):
        next(gen)
        arm.step(DT)
        seen.append(list(arm.q))
    for steps in (0, 1, 7, 20):
        assert lib_state.get_actual_joint_positions_history(host, steps) == seen[-1 - steps]
    assert lib_state.get_actual_joint_positions_history(host, 10 * HISTORY_STEPS) == arm.history.ago(
        HISTORY_STEPS - 1
    )
    with pytest.raises(ScriptRuntimeError):
        lib_state.get_actual_joint_positions_history(host, -1)


def test_forces_torques_and_temperatures_are_those_of_an_arm_touching_nothing() -> None:
    host = _host()
    assert lib_state.get_tcp_force(host) == [0.0] * 6
    assert lib_state.get_joint_torques(host) == [0.0] * 6
    assert lib_state.get_joint_temp(host, 3) == lib_state.JOINT_TEMPERATURE
    with pytest.raises(ScriptRuntimeError):
        lib_state.get_joint_temp(host, 6)


def test_tcp_force_and_force_read_the_arms_measured_wrench() -> None:
    """On f5f0e26 get_tcp_force was always zero and force() was not simulated."""
    host = _host()
    assert list(lib_state.get_tcp_force(host)) == [0.0] * 6
    assert lib_state.force(host) == 0.0
    host.arm.tcp_force = [3.0, -4.0, 12.0, 0.5, 0.1, -0.2]
    wrench = lib_state.get_tcp_force(host)
    assert isinstance(wrench, UrPose)
    assert list(wrench) == [3.0, -4.0, 12.0, 0.5, 0.1, -0.2]
    assert lib_state.force(host) == pytest.approx(13.0)


def test_tool_accelerometer_reads_gravity_in_the_tcp_frame() -> None:
    """A still tool reads the reaction to gravity: +9.82 along whichever TCP axis points up."""
    host = _host()
    arm = host.arm
    reading = lib_state.get_tool_accelerometer_reading(host)
    assert math.sqrt(sum(a * a for a in reading)) == pytest.approx(9.82)
    rotation = frames.frame_of_pose(lib_state.get_actual_tcp_pose(host))
    up_in_base = [sum(rotation[3 * i + k] * reading[k] for k in range(3)) for i in range(3)]
    assert up_in_base == pytest.approx([0.0, 0.0, 9.82], abs=1e-9)
    arm.tcp_offset = [0.0, 0.0, 0.1, math.pi / 2, 0.0, 0.0]  # the TCP turned: the reading turns with it
    turned = lib_state.get_tool_accelerometer_reading(host)
    assert list(turned) != pytest.approx(list(reading), abs=1e-3)
    assert math.sqrt(sum(a * a for a in turned)) == pytest.approx(9.82)
    arm.gravity = [0.0, 9.82, 0.0]  # a robot mounted on a wall
    walled = lib_state.get_tool_accelerometer_reading(host)
    rotation = frames.frame_of_pose(lib_state.get_actual_tcp_pose(host))
    assert [sum(rotation[3 * i + k] * walled[k] for k in range(3)) for i in range(3)] == pytest.approx(
        [0.0, 9.82, 0.0], abs=1e-9
    )


def test_the_reports_read_the_same_accelerometer_as_the_builtin() -> None:
    """RTDE ``actual_tool_accelerometer`` (not offered before) and the real-time interface's reading
    (a constant (0, 0, 9.82) before) are the builtin's, for a turned TCP too."""
    from urdaemon.fakeur.reports import output_getter, realtime_state

    host = _host()
    host.arm.tcp_offset = [0.0, 0.0, 0.1, math.pi / 2, 0.0, 0.0]
    reading = tuple(lib_state.get_tool_accelerometer_reading(host))
    getter = output_getter("actual_tool_accelerometer", "VECTOR3D", None)  # type: ignore[arg-type]
    assert tuple(getter(host.arm)) == pytest.approx(reading)
    assert tuple(realtime_state(host.arm).tool_accelerometer_values) == pytest.approx(reading)
    assert reading != pytest.approx((0.0, 0.0, 9.82), abs=1e-3)


def test_free_air_getters_of_a_still_robot() -> None:
    host = _host()
    assert lib_state.get_tool_current(host) == 0.0
    assert lib_state.get_controller_temp(host) == lib_state.CONTROLLER_TEMPERATURE
    assert lib_state.get_tool_temp(host) == lib_state.JOINT_TEMPERATURE
    before = list(host.arm.q)
    lib_state.reset_revolution_counter(host, [0.0] * 6)
    assert host.arm.q == before, "every joint of the model is limited to ±2π: nothing to unwind"
    with pytest.raises(ScriptRuntimeError, match="qNear"):
        lib_state.reset_revolution_counter(host, [0.0] * 5)
