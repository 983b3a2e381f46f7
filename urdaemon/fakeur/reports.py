"""What a fake controller reports of its arm: the primary/secondary robot state (10 Hz), the real-time
interface's state (every cycle) and the RTDE output variables (read per client recipe).

Pure functions of the arm (and of the controller's RTDE input registers): no sockets, no clock. The
target joint positions and speeds are the arm's own (``arm.target_q``/``target_qd``: where the played
motion is now meant to be), the TCP speeds are the joint speeds through the arm's kinematics, and a
program that is pausing (its speed scaling ramping to 0) is reported as playing until it is paused,
as a controller reports it.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable
from typing import Any

from urdaemon.description.urmodels import UrModel
from urdaemon.fakeur.fake_arm import FakeArm, arm_payload, joint_torques
from urdaemon.fakeur.urscript.lib_io import analog_output_level
from urdaemon.fakeur.urscript.lib_motion import tool_speed
from urdaemon.fakeur.urscript.lib_state import JOINT_TEMPERATURE, tool_accelerometer
from urdaemon.fakeur.urscript.script_host import InputRegisters
from urdaemon.model import RobotMode, SafetyMode
from urdaemon.protocols import primary as prim
from urdaemon.protocols import realtime as rt
from urdaemon.protocols.rtde_variables import RuntimeState

__all__ = ["KINEMATICS_CALIBRATED", "joint_mode", "output_getter", "realtime_state", "robot_state"]

KINEMATICS_CALIBRATED = 2
"""KINEMATICS_INFO ``calibration_status`` of a calibrated arm: 2, "linearized", what a calibrated robot
reports and urcl's calibration example checks for (URSim, which has no calibration, sends 0)."""
_PROGRAM_STATES = {
    RuntimeState.PLAYING: 2.0,
    RuntimeState.PAUSING: 2.0,  # playing until paused, as a controller says
    RuntimeState.PAUSED: 3.0,
}
"""Real-time interface ``program_state`` (1 stopped, 2 playing, 3 paused) by runtime state."""


JOINT_RUNNING_MODE = 253
"""A joint's mode while its brakes are released and it is controlled (UR's client interface tables)."""
JOINT_IDLE_MODE = 255
"""A powered joint with its brakes engaged."""
JOINT_POWER_OFF_MODE = 239
"""A joint without power."""
JOINT_BACKDRIVE_MODE = 238
"""A joint being back-driven (robot mode BACKDRIVE: brakes released by hand, no control)."""
_JOINT_MODES = {
    RobotMode.RUNNING: JOINT_RUNNING_MODE,
    RobotMode.BACKDRIVE: JOINT_BACKDRIVE_MODE,
    RobotMode.IDLE: JOINT_IDLE_MODE,
    RobotMode.POWER_ON: JOINT_IDLE_MODE,
}


def joint_mode(arm: FakeArm) -> int:
    """The mode every joint of ``arm`` is in, by its robot mode: one value for every interface that
    reports it (RTDE's ``joint_mode`` and ``tool_mode``, the real-time interface, the primary
    interface's joint and tool data); a joint without power is in JOINT_POWER_OFF_MODE."""
    return _JOINT_MODES.get(arm.robot_mode, JOINT_POWER_OFF_MODE)


def _six(values: list[float]) -> tuple[float, float, float, float, float, float]:
    return (values[0], values[1], values[2], values[3], values[4], values[5])


def _torques(arm: FakeArm) -> tuple[float, ...]:
    """N·m: the joint torques of ``arm`` now (its dynamics, computed at most once a cycle). The fake arm
    follows its model exactly, so the target moments and the torques its currents stand for are one
    value: RTDE's ``target_moment`` and ``actual_current_as_torque``, the real-time ``m_target``."""
    return tuple(joint_torques(arm))


_MOMENTA: weakref.WeakKeyDictionary[FakeArm, tuple[float, float]] = weakref.WeakKeyDictionary()
"""Each arm's last ``actual_momentum`` and the timestamp (cycle) it is for."""


def _momentum(arm: FakeArm) -> float:
    """kg·m/s: RTDE's ``actual_momentum``, the norm of the arm's Cartesian linear momentum (its links and
    payload, by the model's masses and centres of mass). Computed only for a recipe that names it, at most
    once a cycle however many clients ask; 0 without computing while the joints are still."""
    kept = _MOMENTA.get(arm)
    if kept is not None and kept[0] == arm.timestamp:
        return kept[1]
    qd = arm.qd
    value = 0.0
    if any(qd):
        value = arm.drive.dynamics.linear_momentum(arm.q, qd, arm_payload(arm))
    _MOMENTA[arm] = (arm.timestamp, value)
    return value


def realtime_state(arm: FakeArm) -> rt.RealtimeState:
    """The real-time interface's (30003) state of ``arm``, sent every cycle."""
    q, qd, qdd = tuple(arm.q), tuple(arm.qd), tuple(arm.qdd)
    target_q, target_qd = tuple(arm.target_q), tuple(arm.target_qd)
    pose = arm.actual_tcp_pose()
    running = arm.robot_mode is RobotMode.RUNNING
    program_state = _PROGRAM_STATES.get(arm.runtime_state, 1.0)
    return rt.RealtimeState(
        time=arm.timestamp,
        q_target=target_q,
        qd_target=target_qd,
        qdd_target=qdd,
        i_target=tuple(arm.current),
        m_target=_torques(arm),
        q_actual=q,
        qd_actual=qd,
        i_actual=tuple(arm.current),
        i_control=tuple(arm.current),
        tool_vector_actual=pose,
        tool_vector_target=pose,
        tcp_force=_six(arm.tcp_force),
        digital_input_bits=float(arm.io.digital_in),
        motor_temperatures=(JOINT_TEMPERATURE,) * 6,
        controller_timer=0.0002,
        robot_mode=float(arm.robot_mode),
        joint_modes=(float(joint_mode(arm)),) * 6,
        safety_mode=float(arm.safety_mode),
        tool_accelerometer_values=tool_accelerometer(arm),
        speed_scaling=arm.speed_scaling,
        v_main=48.0,
        v_robot=48.0 if running else 0.0,
        v_actual=(48.0 if running else 0.0,) * 6,
        digital_outputs=float(arm.io.digital_out),
        program_state=program_state,
        safety_status=float(arm.safety_mode),
        payload_mass=arm.payload_mass,
        payload_cog=tuple(arm.payload_cog),
        payload_inertia=tuple(arm.payload_inertia),
    )


def robot_state(
    arm: FakeArm, model: UrModel, controller_version: tuple[int, int, int, int]
) -> prim.RobotState:
    """The robot state of ``arm`` on the primary and secondary interfaces (10 Hz)."""
    powered = arm.robot_mode in (RobotMode.IDLE, RobotMode.RUNNING, RobotMode.POWER_ON)
    modes = joint_mode(arm)
    dh = arm.dh
    return prim.RobotState(
        (
            _robot_mode_data(arm, powered, controller_version),
            _joint_data(arm, modes),
            prim.CartesianInfo(tcp_pose=arm.actual_tcp_pose(), tcp_offset=tuple(arm.tcp_offset)),
            prim.KinematicsInfo(
                checksum=(0xFFFFFFFF,) * 6,
                dh_theta=dh.theta,
                dh_a=dh.a,
                dh_d=dh.d,
                dh_alpha=dh.alpha,
                calibration_status=KINEMATICS_CALIBRATED,
            ),
            _masterboard_data(arm, powered),
            prim.ToolData(tool_output_voltage=arm.io.tool_voltage, tool_mode=modes),
            _configuration_data(arm, model, controller_version),
            prim.ForceModeData(wrench=_six(arm.tcp_force)),
            prim.AdditionalInfo(),
        )
    )


def _robot_mode_data(
    arm: FakeArm, powered: bool, controller_version: tuple[int, int, int, int]
) -> prim.RobotModeData:
    """The robot mode package: power, stops, program run state and speed."""
    return prim.RobotModeData(
        timestamp=int(arm.timestamp * 1000),
        is_real_robot_connected=True,
        is_real_robot_enabled=True,
        is_robot_power_on=powered,
        is_emergency_stopped=arm.safety_mode
        in (SafetyMode.ROBOT_EMERGENCY_STOP, SafetyMode.SYSTEM_EMERGENCY_STOP),
        is_protective_stopped=arm.safety_mode is SafetyMode.PROTECTIVE_STOP,
        is_program_running=arm.program_running,
        is_program_paused=arm.runtime_state is RuntimeState.PAUSED,
        robot_mode=int(arm.robot_mode),
        control_mode=0,
        target_speed_fraction=arm.speed_slider,
        speed_scaling=arm.speed_scaling,
        target_speed_fraction_limit=1.0,
        reserved=0 if controller_version[0] >= 5 else None,  # CB3: 46 bytes
    )


def _joint_data(arm: FakeArm, modes: int) -> prim.JointData:
    """The joint data package: positions, speeds, currents and joint modes."""
    return prim.JointData(
        q_actual=tuple(arm.q),
        q_target=tuple(arm.target_q),
        qd_actual=tuple(arm.qd),
        i_actual=tuple(arm.current),
        v_actual=(48.0,) * 6,
        t_motor=(JOINT_TEMPERATURE,) * 6,
        t_micro=(JOINT_TEMPERATURE,) * 6,
        joint_mode=(modes,) * 6,
    )


def _masterboard_data(arm: FakeArm, powered: bool) -> prim.MasterboardData:
    """The masterboard package: the controller's digital and analog IO and the 48 V supply."""
    return prim.MasterboardData(
        digital_input_bits=arm.io.digital_in & 0xFFFF,
        digital_output_bits=arm.io.digital_out & 0xFFFF,
        analog_output_domain0=(arm.io.analog_out_types >> 2) & 1,
        analog_output_domain1=(arm.io.analog_out_types >> 3) & 1,
        analog_output0=analog_output_level(arm.io, 0),
        analog_output1=analog_output_level(arm.io, 1),
        robot_voltage_48v=48.0 if powered else 0.0,
        safety_mode=int(arm.safety_mode),
    )


def _configuration_data(
    arm: FakeArm, model: UrModel, controller_version: tuple[int, int, int, int]
) -> prim.ConfigurationData:
    """The configuration package: joint limits, defaults, DH parameters and hardware types."""
    dh = arm.dh
    return prim.ConfigurationData(
        joint_min_limit=tuple(max(v, -6.335) for v in arm.min_position),
        joint_max_limit=tuple(min(v, 6.335) for v in arm.max_position),
        joint_max_speed=tuple(arm.max_velocity),
        joint_max_acceleration=(40.0,) * 6,
        v_joint_default=1.0472,
        a_joint_default=1.3963,
        v_tool_default=0.25,
        a_tool_default=1.2,
        eq_radius=0.25,
        dh_a=dh.a,
        dh_d=dh.d,
        dh_alpha=dh.alpha,
        dh_theta=dh.theta,
        masterboard_version=6,
        controller_box_type=4 if controller_version[0] >= 5 else 2,
        robot_type=model.robot_type,
        robot_sub_type=3 if controller_version[0] >= 5 else 2,
    )


def output_getter(name: str, rtde_type: str, inputs: InputRegisters) -> Callable[[FakeArm], Any]:
    """How to read output ``name`` off the arm (zero of its type for what the fake does not model)."""
    getter = _OUTPUTS.get(name)
    if getter is not None:
        return getter
    if "_bit_registers" in name:  # a UINT32 word of bits 0..31 or 32..63
        low = 0 if name.endswith("0_to_31") else 32
        if name.startswith("input_"):
            return lambda arm: _word(inputs.bits, low)
        return lambda arm: _word(arm.io.registers_bit, low)
    if name.startswith("input_int_register_"):
        at = int(name.rsplit("_", 1)[1])
        return lambda arm: inputs.ints.get(at, 0)
    if name.startswith("input_double_register_"):
        at = int(name.rsplit("_", 1)[1])
        return lambda arm: inputs.doubles.get(at, 0.0)
    if name.startswith("input_bit_register_"):
        at = int(name.rsplit("_", 1)[1])
        return lambda arm: inputs.bits.get(at, False)
    if name.startswith("output_int_register_"):
        index = int(name.rsplit("_", 1)[1])
        return lambda arm: arm.io.registers_int.get(index, 0)
    if name.startswith("output_double_register_"):
        index = int(name.rsplit("_", 1)[1])
        return lambda arm: arm.io.registers_double.get(index, 0.0)
    if name.startswith("output_bit_register_"):
        index = int(name.rsplit("_", 1)[1])
        return lambda arm: arm.io.registers_bit.get(index, False)
    zero = _ZEROS[rtde_type]
    return lambda arm: zero


def _word(bits: dict[int, bool], low: int) -> int:
    """Bits ``low``..``low + 31`` of ``bits`` as a UINT32 (bit ``low`` the least significant)."""
    word = 0
    for index, value in bits.items():
        if value and low <= index < low + 32:
            word |= 1 << (index - low)
    return word


_ZEROS: dict[str, Any] = {
    "BOOL": False,
    "UINT8": 0,
    "UINT32": 0,
    "UINT64": 0,
    "INT32": 0,
    "DOUBLE": 0.0,
    "VECTOR3D": (0.0, 0.0, 0.0),
    "VECTOR6D": (0.0,) * 6,
    "VECTOR6INT32": (0,) * 6,
    "VECTOR6UINT32": (0,) * 6,
}

_OUTPUTS: dict[str, Callable[[FakeArm], Any]] = {
    "timestamp": lambda arm: arm.timestamp,
    "actual_q": lambda arm: tuple(arm.q),
    "actual_qd": lambda arm: tuple(arm.qd),
    "actual_qdd": lambda arm: tuple(arm.qdd),
    "target_q": lambda arm: tuple(arm.target_q),
    "target_qd": lambda arm: tuple(arm.target_qd),
    "target_qdd": lambda arm: tuple(arm.qdd),
    "actual_current": lambda arm: tuple(arm.current),
    "target_current": lambda arm: tuple(arm.current),
    "target_moment": _torques,
    "actual_current_as_torque": _torques,
    "actual_momentum": _momentum,
    "joint_temperatures": lambda arm: (JOINT_TEMPERATURE,) * 6,
    "joint_mode": lambda arm: (joint_mode(arm),) * 6,
    "speed_scaling": lambda arm: arm.speed_scaling,
    "target_speed_fraction": lambda arm: arm.speed_slider,
    "runtime_state": lambda arm: int(arm.runtime_state),
    "actual_TCP_pose": lambda arm: arm.actual_tcp_pose(),
    "target_TCP_pose": lambda arm: arm.actual_tcp_pose(),
    "actual_TCP_speed": lambda arm: tuple(tool_speed(arm, arm.q, arm.qd)),
    "target_TCP_speed": lambda arm: tuple(tool_speed(arm, arm.target_q, arm.target_qd)),
    "actual_TCP_force": lambda arm: tuple(arm.tcp_force),
    "actual_tool_accelerometer": tool_accelerometer,
    "actual_digital_input_bits": lambda arm: arm.io.digital_in,
    "actual_digital_output_bits": lambda arm: arm.io.digital_out,
    "standard_analog_input0": lambda arm: arm.io.analog_in[0],
    "standard_analog_input1": lambda arm: arm.io.analog_in[1],
    "standard_analog_output0": lambda arm: analog_output_level(arm.io, 0),
    "standard_analog_output1": lambda arm: analog_output_level(arm.io, 1),
    "analog_io_types": lambda arm: arm.io.analog_out_types,
    "tool_analog_input0": lambda arm: arm.io.tool_analog_in[0],
    "tool_analog_input1": lambda arm: arm.io.tool_analog_in[1],
    "tool_output_voltage": lambda arm: arm.io.tool_voltage,
    "tool_mode": joint_mode,
    "tool_temperature": lambda arm: JOINT_TEMPERATURE,
    "robot_mode": lambda arm: int(arm.robot_mode),
    "safety_mode": lambda arm: int(arm.safety_mode),
    "safety_status": lambda arm: int(arm.safety_mode),
    "robot_status_bits": lambda arm: arm.life.robot_status_bits,
    "safety_status_bits": lambda arm: arm.life.safety_status_bits,
    "tcp_offset": lambda arm: tuple(arm.tcp_offset),
    "payload": lambda arm: arm.payload_mass,
    "payload_cog": lambda arm: tuple(arm.payload_cog),
    "payload_inertia": lambda arm: tuple(arm.payload_inertia),
    "actual_main_voltage": lambda arm: 48.0,
    "actual_robot_voltage": lambda arm: 48.0,
    "actual_robot_current": lambda arm: 0.5,
    "actual_joint_voltage": lambda arm: (48.0,) * 6,
    "actual_execution_time": lambda arm: 0.1,
}
