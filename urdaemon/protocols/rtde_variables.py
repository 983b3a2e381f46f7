"""The RTDE variables a controller knows, by name, with their wire type (reference §1.5, §1.10).

Sources (facts only, nothing copied):

* UR's RTDE guide (docs.universal-robots.com, "Real-Time Data Exchange (RTDE) Guide"): the field
  tables for outputs and inputs;
* urcl ``src/rtde/data_package.cpp`` (UniversalRobots/Universal_Robots_Client_Library 2.14.0,
  commit c5d1e26): the same names with their C++ types, grouped as inputs, input/output and
  outputs; urcl's integration tests check that table against UR's documentation;
* UR's ``RTDE_Python_Client_Library`` ``examples/record_configuration.xml`` (commit 647788c, "Document
  all possible input fields"): the output and input lists again, with RTDE type names.

Two facts a naive table gets wrong, both confirmed by the sources above:

* the single-bit registers ``input_bit_register_X`` / ``output_bit_register_X`` exist only for
  X = 64…127. Bits 0…63 are reachable only through the UINT32 words ``*_bit_registers0_to_31`` and
  ``*_bit_registers32_to_63`` (urcl removed ``*_bit_register_0..63`` in PR #385 because "they are not
  published by the robot controller"; the guide and UR's own client list 64…127 only). So the fake
  answers NOT_FOUND for ``input_bit_register_0`` (a controller's answer was not captured here);
* the input registers (``input_bit_registers*``, ``input_bit_register_X``, ``input_int_register_X``,
  ``input_double_register_X``) are also readable as *outputs*; the output registers are outputs only.

``tool_digital_output_mask`` / ``tool_digital_output`` are inputs that urcl marks "not in official
docs"; UR's own client lists them and the ROS 2 driver's input recipe uses them, so a controller
knows them. Names added by recent controllers (``control_step``, ``target_base_wrench``, …) are
included: the fake controller models a current e-Series controller.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Final

__all__ = [
    "BIT_REGISTER_FIRST",
    "BIT_REGISTER_LAST",
    "BOOL",
    "DOUBLE",
    "INPUT_VARIABLES",
    "INT32",
    "IN_USE",
    "NOT_FOUND",
    "NUMBER_REGISTER_COUNT",
    "OUTPUT_VARIABLES",
    "POWER_ON_BIT",
    "PROGRAM_RUNNING_BIT",
    "RTDE_TYPES",
    "UINT8",
    "UINT32",
    "UINT64",
    "VECTOR3D",
    "VECTOR6D",
    "VECTOR6INT32",
    "VECTOR6UINT32",
    "RuntimeState",
    "input_types",
    "output_types",
    "type_size",
]

# Type names exactly as a controller writes them in SETUP_OUTPUTS / SETUP_INPUTS replies (§1.5).
BOOL: Final = "BOOL"
UINT8: Final = "UINT8"
UINT32: Final = "UINT32"
UINT64: Final = "UINT64"
INT32: Final = "INT32"
DOUBLE: Final = "DOUBLE"
VECTOR3D: Final = "VECTOR3D"
VECTOR6D: Final = "VECTOR6D"
VECTOR6INT32: Final = "VECTOR6INT32"
VECTOR6UINT32: Final = "VECTOR6UINT32"
NOT_FOUND: Final = "NOT_FOUND"
"""Setup-reply token: the controller does not know this name (in this direction)."""
IN_USE: Final = "IN_USE"
"""Setup-reply token: another client (or interface) already owns this input."""

_SIZES: Final[Mapping[str, int]] = MappingProxyType(
    {
        BOOL: 1,
        UINT8: 1,
        UINT32: 4,
        UINT64: 8,
        INT32: 4,
        DOUBLE: 8,
        VECTOR3D: 24,
        VECTOR6D: 48,
        VECTOR6INT32: 24,
        VECTOR6UINT32: 24,
    }
)

RTDE_TYPES: Final[frozenset[str]] = frozenset(_SIZES)
"""Every value type a recipe can hold (NOT_FOUND and IN_USE are answers, not types)."""


class RuntimeState(enum.IntEnum):
    """The values of the UINT32 output ``runtime_state``: the program's run state (§1.9)."""

    STOPPING = 0
    STOPPED = 1
    PLAYING = 2
    PAUSING = 3
    PAUSED = 4
    RESUMING = 5


# The bits of the UINT32 output ``robot_status_bits`` (§1.9), as masks.
POWER_ON_BIT: Final = 1 << 0
"""``robot_status_bits``: the arm is powered on."""
PROGRAM_RUNNING_BIT: Final = 1 << 1
"""``robot_status_bits``: a program runs (it plays, or pauses and has not yet stopped)."""

BIT_REGISTER_FIRST: Final = 64
"""Lowest single-bit register index a controller publishes (bits 0..63 only as UINT32 words)."""
BIT_REGISTER_LAST: Final = 127
NUMBER_REGISTER_COUNT: Final = 48
"""int/double registers: indices 0..47 each way (§1.8: 0..23 said to be for fieldbus, unverified)."""


def type_size(rtde_type: str) -> int:
    """Bytes one value of ``rtde_type`` takes on the wire (§1.5); ValueError for anything else."""
    try:
        return _SIZES[rtde_type]
    except KeyError:
        raise ValueError(f"not an RTDE value type: {rtde_type!r}") from None


def _registers(direction: str) -> dict[str, str]:
    """The general-purpose registers of one direction ("input" or "output")."""
    table = {
        f"{direction}_bit_registers0_to_31": UINT32,
        f"{direction}_bit_registers32_to_63": UINT32,
    }
    for n in range(BIT_REGISTER_FIRST, BIT_REGISTER_LAST + 1):
        table[f"{direction}_bit_register_{n}"] = BOOL
    for n in range(NUMBER_REGISTER_COUNT):
        table[f"{direction}_int_register_{n}"] = INT32
    for n in range(NUMBER_REGISTER_COUNT):
        table[f"{direction}_double_register_{n}"] = DOUBLE
    return table


# Robot -> client fields (urcl's order), registers added below.
_OUTPUT_FIELDS: Final[dict[str, str]] = {
    "timestamp": DOUBLE,  # s since controller start
    "target_q": VECTOR6D,
    "target_qd": VECTOR6D,
    "target_qdd": VECTOR6D,
    "target_current": VECTOR6D,
    "target_moment": VECTOR6D,
    "actual_q": VECTOR6D,
    "actual_qd": VECTOR6D,
    "actual_current": VECTOR6D,
    "actual_current_window": VECTOR6D,
    "actual_current_as_torque": VECTOR6D,
    "joint_control_output": VECTOR6D,
    "actual_TCP_pose": VECTOR6D,
    "actual_TCP_speed": VECTOR6D,
    "actual_TCP_force": VECTOR6D,
    "target_TCP_pose": VECTOR6D,
    "target_TCP_speed": VECTOR6D,
    "tcp_offset": VECTOR6D,
    "actual_TCP_acceleration": VECTOR6D,
    "target_TCP_acceleration": VECTOR6D,
    "actual_digital_input_bits": UINT64,
    "actual_configurable_digital_input_bits": UINT64,
    "joint_temperatures": VECTOR6D,
    "actual_execution_time": DOUBLE,
    "target_execution_time": DOUBLE,
    "robot_mode": INT32,
    "joint_mode": VECTOR6INT32,
    "safety_mode": INT32,
    "safety_status": INT32,
    "actual_tool_accelerometer": VECTOR3D,
    "speed_scaling": DOUBLE,
    "target_speed_fraction": DOUBLE,
    "actual_momentum": DOUBLE,
    "actual_main_voltage": DOUBLE,
    "actual_robot_voltage": DOUBLE,
    "actual_robot_current": DOUBLE,
    "actual_joint_voltage": VECTOR6D,
    "actual_digital_output_bits": UINT64,
    "actual_configurable_digital_output_bits": UINT64,
    "runtime_state": UINT32,
    "elbow_position": VECTOR3D,
    "elbow_velocity": VECTOR3D,
    "robot_status_bits": UINT32,
    "safety_status_bits": UINT32,
    "analog_io_types": UINT32,
    "standard_analog_input0": DOUBLE,
    "standard_analog_input1": DOUBLE,
    "standard_analog_output0": DOUBLE,  # read-back; the writable input is standard_analog_output_0
    "standard_analog_output1": DOUBLE,
    "io_current": DOUBLE,
    "actual_robot_energy_consumed": DOUBLE,
    "actual_robot_braking_energy_dissipated": DOUBLE,
    "encoder0_raw": INT32,
    "encoder1_raw": INT32,
    "euromap67_input_bits": UINT32,
    "euromap67_output_bits": UINT32,
    "euromap67_24V_voltage": DOUBLE,
    "euromap67_24V_current": DOUBLE,
    "tool_mode": UINT32,
    "tool_analog_input_types": UINT32,
    "tool_analog_input0": DOUBLE,
    "tool_analog_input1": DOUBLE,
    "tool_output_voltage": INT32,
    "tool_output_current": DOUBLE,
    "tool_temperature": DOUBLE,
    "tool_output_mode": UINT8,
    "tool_digital_output0_mode": UINT8,
    "tool_digital_output1_mode": UINT8,
    "tcp_force_scalar": DOUBLE,
    "joint_position_deviation_ratio": DOUBLE,
    "collision_detection_ratio": DOUBLE,
    "ft_raw_wrench": VECTOR6D,
    "wrench_calc_from_currents": VECTOR6D,
    "payload": DOUBLE,
    "payload_cog": VECTOR3D,
    "payload_inertia": VECTOR6D,
    "script_control_line": UINT32,
    "time_scale_source": INT32,
    "target_gravity": VECTOR3D,
    "target_base_acceleration": VECTOR6D,
    "control_step": UINT64,
    "target_base_wrench": VECTOR6D,
}

# Client -> robot fields (what SETUP_INPUTS accepts), input registers added below.
_INPUT_FIELDS: Final[dict[str, str]] = {
    "speed_slider_mask": UINT32,
    "speed_slider_fraction": DOUBLE,
    "standard_digital_output_mask": UINT8,
    "standard_digital_output": UINT8,
    "configurable_digital_output_mask": UINT8,
    "configurable_digital_output": UINT8,
    "tool_digital_output_mask": UINT8,  # urcl: "not in official docs"; UR's client and the driver use it
    "tool_digital_output": UINT8,
    "standard_analog_output_mask": UINT8,
    "standard_analog_output_type": UINT8,
    "standard_analog_output_0": DOUBLE,
    "standard_analog_output_1": DOUBLE,
    "external_force_torque": VECTOR6D,  # used only while the script calls ft_rtde_input_enable
}

OUTPUT_VARIABLES: Final[Mapping[str, str]] = MappingProxyType(
    {**_OUTPUT_FIELDS, **_registers("output"), **_registers("input")}
)
"""Every name SETUP_OUTPUTS accepts → its type; input registers are readable as outputs too."""

INPUT_VARIABLES: Final[Mapping[str, str]] = MappingProxyType({**_INPUT_FIELDS, **_registers("input")})
"""Every name SETUP_INPUTS accepts → its type."""


def output_types(names: Iterable[str]) -> tuple[str, ...]:
    """The SETUP_OUTPUTS answer a controller gives for ``names``: a type each, NOT_FOUND if unknown."""
    return tuple(OUTPUT_VARIABLES.get(name, NOT_FOUND) for name in names)


def input_types(names: Iterable[str]) -> tuple[str, ...]:
    """The SETUP_INPUTS answer for ``names`` ignoring ownership: a type each, NOT_FOUND if unknown.

    IN_USE depends on which other clients own which inputs; the fake controller decides that.
    """
    return tuple(INPUT_VARIABLES.get(name, NOT_FOUND) for name in names)
