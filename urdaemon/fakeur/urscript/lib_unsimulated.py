"""The builtins the fake controller does not simulate, on purpose, each with the reason.

A program that mentions one compiles (the controller knows the name); calling it stops the program with
a runtime error "<name>: not simulated by the fake controller: <reason>" - never a silent no-op.
:data:`NOT_SIMULATED` is the one list: the documentation quotes it, and a test checks that every builtin
of the table (functions.yaml, every series and version) is either implemented by a library or listed
here, so a function added to the table cannot go unimplemented unnoticed.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any, Final

from urdaemon.fakeur.urscript.runtime import BUILTINS, ScriptRuntimeError, builtin
from urdaemon.fakeur.urscript.script_host import ScriptHost

__all__ = ["NOT_SIMULATED", "REASONS"]

_CONVEYOR = "needs a conveyor encoder, which the fake has none of"
_MODBUS = "talks to external Modbus devices of the installation, which the fake has none of"
_EUROMAP = "needs a Euromap67 interface to a moulding machine, which the fake has none of"
_SCREW = "needs a screwdriving tool, which the fake has none of"
_OPERATOR = "waits for an operator's answer on the teach pendant, which the fake has none of"
_PATH_OFFSET = "offsets a moving path in real time; the fake's motion model has no path offset"
_WORLD = "the world model of named frames (PolyScope 5.2x) is not modelled by the fake yet"
_MOTION = "a motion planner option the fake's motion model does not have yet"
_NOT_YET = "not modelled by the fake yet"

REASONS: Final[Mapping[str, tuple[str, ...]]] = MappingProxyType(
    {
        _CONVEYOR: (
            "conveyor_pulse_decode",
            "encoder_enable_pulse_decode",
            "encoder_enable_set_tick_count",
            "encoder_get_tick_count",
            "encoder_set_tick_count",
            "encoder_unwind_delta_tick_count",
            "get_conveyor_tick_count",
            "set_conveyor_tick_count",
            "stop_conveyor_tracking",
            "track_conveyor_circular",
            "track_conveyor_linear",
        ),
        _MODBUS: (
            "modbus_add_rw_signal",
            "modbus_add_signal",
            "modbus_delete_signal",
            "modbus_get_error",
            "modbus_get_signal_status",
            "modbus_get_time_since_signal_invalid",
            "modbus_reset_connection",
            "modbus_send_custom_command",
            "modbus_set_digital_input_action",
            "modbus_set_output_register",
            "modbus_set_output_signal",
            "modbus_set_runstate_dependent_choice",
            "modbus_set_signal_update_frequency",
            "modbus_set_signal_watchdog",
        ),
        _EUROMAP: (
            "get_euromap_input",
            "get_euromap_output",
            "set_euromap_output",
            "set_euromap_runstate_dependent_choice",
        ),
        _SCREW: ("screw_driving", "end_screw_driving"),
        _OPERATOR: (
            "request_boolean_from_primary_client",
            "request_float_from_primary_client",
            "request_integer_from_primary_client",
            "request_string_from_primary_client",
        ),
        "calls XML-RPC servers on other hosts; the fake has no XML-RPC client": ("rpc_factory",),
        _PATH_OFFSET: (
            "path_offset_disable",
            "path_offset_enable",
            "path_offset_get",
            "path_offset_set",
            "path_offset_set_alpha_filter",
            "path_offset_set_max_offset",
        ),
        _WORLD: (
            "add_frame",
            "attach_frame",
            "convert_pose",
            "delete_all_frames",
            "delete_frame",
            "frame_tracking_disable",
            "frame_tracking_enable",
            "get_children",
            "get_frame_parent",
            "get_pose",
            "is_frame",
            "move_frame",
            "reset_world_model",
            "set_mass_properties",
            "set_payload_from_attached_frames",
        ),
        _MOTION: (
            "jerk_gain_scaling_get",
            "jerk_gain_scaling_set",
            "motion_version_get",
            "motion_version_set",
            "optimovel",
        ),
        _NOT_YET: (
            "estimate_payload",
            "freedrive_mode_no_incorrect_payload_check",
            "get_rtde_value",
            "time",
            "tool_wrench_limit_disable",
            "tool_wrench_limit_set",
        ),
    }
)
"""Why each group of builtins is not simulated: reason -> names."""

NOT_SIMULATED: Final[Mapping[str, str]] = MappingProxyType(
    {name: reason for reason, names in REASONS.items() for name in names}
)
"""Every builtin of the table the fake does not simulate, by name: the reason."""


def _refuse(name: str, reason: str) -> Callable[..., Any]:
    def refuse(host: ScriptHost, *args: Any) -> Any:
        raise ScriptRuntimeError(f"{name}: not simulated by the fake controller: {reason}")

    refuse.__name__ = name
    return refuse


for _name, _reason in NOT_SIMULATED.items():
    if _name not in BUILTINS:  # a library that implements it meanwhile wins (the coverage test flags it)
        builtin(_name)(_refuse(_name, _reason))
