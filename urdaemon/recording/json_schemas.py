"""JSON Schemas of the messages the recorder keeps as JSON: those no standard ROS 2 type fits.

They describe the messages of docs/keys.md (draft 2020-12) so that Foxglove and other readers know
each field's type: enough to plot a number or list an event, not a second check of the messages
(the daemon's codec makes them; unknown fields are allowed, so a newer daemon's recording still
reads).
"""

from __future__ import annotations

from typing import Any

__all__ = ["JSON_SCHEMAS"]

_NUMBER = {"type": ["number", "null"]}
_INT = {"type": "integer"}
_STRING = {"type": "string"}
_BOOL = {"type": "boolean"}
_NUMBERS = {"type": "array", "items": _NUMBER}
_BOOLS = {"type": "array", "items": _BOOL}
_TIMES = {
    "host_time_ns": {"type": "integer", "description": "Unix time (ns) of what the message describes"},
    "controller_time": {"type": ["number", "null"], "description": "the controller's clock (s)"},
}


def _object(title: str, properties: dict[str, Any], required: tuple[str, ...] = ()) -> dict[str, Any]:
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "type": "object",
        "properties": {"v": _INT, "robot": _STRING, **properties, **_TIMES},
        "required": ["host_time_ns", *required],
    }


_LEASE = {
    "type": ["object", "null"],
    "properties": {"holder": _STRING, "fingerprint": _STRING, "since": {"type": "number"}},
}

_OUTPUT = {
    "type": "object",
    "description": "a servo arm's board or serial port (backends/servo/writer.py)",
    "properties": {
        "output": _STRING,
        "state": {"type": "string", "enum": ["connecting", "ok", "lost", "stopped"]},
        "error": _STRING,
        **dict.fromkeys(("frames", "transfers", "superseded", "failures", "reopened"), _INT),
    },
}

_STATUS = _object(
    "urdaemon/Status",
    {
        "backend": _STRING,
        "model": _STRING,
        "lifecycle": _STRING,
        "reason": _STRING,
        "robot_mode": _STRING,
        "safety_mode": _STRING,
        "speed_slider": _NUMBER,
        "speed_scaling": _NUMBER,
        "program_running": _BOOL,
        "ready": _BOOL,
        "active_goal": {"type": ["string", "null"]},
        "rate_hz": _NUMBER,
        "cycles": _INT,
        "missed_cycles": _INT,
        "late_cycles": _INT,
        "restarts": _INT,
        "rejected_stream_commands": _INT,
        "calibration_ok": {"type": ["boolean", "null"]},
        "lease": _LEASE,
        "tcp": {"type": "object", "properties": {"link": _STRING, "pose": _NUMBERS}},
        "outputs": {"type": ["array", "null"], "items": _OUTPUT},
    },
    ("lifecycle",),
)

_IO = _object(
    "urdaemon/Io",
    {
        "digital_out": _BOOLS,
        "configurable_out": _BOOLS,
        "tool_out": _BOOLS,
        "analog_out": _NUMBERS,
        "digital_in": _BOOLS,
        "configurable_in": _BOOLS,
        "tool_in": _BOOLS,
        "analog_in": _NUMBERS,
        "tool_voltage": _NUMBER,
        "payload": {"type": "object", "properties": {"mass": _NUMBER, "cog": _NUMBERS}},
    },
)

_EVENT = _object(
    "urdaemon/Event",
    {
        "kind": _STRING,
        "key": _STRING,
        "reason": _STRING,
        "text": _STRING,
        "action": _STRING,
        "holder": _STRING,
        "fingerprint": _STRING,
    },
    ("kind",),
)

_SERVO = _object(
    "urdaemon/ServoCommand",
    {
        "pwm_frequency_hz": _NUMBER,
        "channels": {"type": "array", "items": _INT, "description": "PCA9685 OFF counts per channel"},
        "pulses_us": {"type": "array", "items": _NUMBER, "description": "pulse per channel (µs; 0: unused)"},
    },
)

_FEEDBACK = _object(
    "urdaemon/GoalFeedback",
    {
        "goal_id": _STRING,
        "time_from_start": _NUMBER,
        "duration": _NUMBER,
        "progress": _NUMBER,
        "desired": _NUMBERS,
        "actual": _NUMBERS,
        "error": _NUMBERS,
    },
    ("goal_id",),
)

_RESULT_FIELDS = {
    "goal_id": _STRING,
    "status": {"type": "string", "enum": ["succeeded", "aborted", "canceled", "preempted"]},
    "reason": _STRING,
    "final_positions": _NUMBERS,
    "final_error": _NUMBERS,
    "duration": _NUMBER,
}

_RESULT = _object("urdaemon/GoalResult", _RESULT_FIELDS, ("goal_id", "status"))

_CELL_RESULT = _object(
    "urdaemon/CellGoalResult",
    {
        "goal_id": _STRING,
        "status": _RESULT_FIELDS["status"],
        "reason": _STRING,
        "robots": {
            "type": "object",
            "additionalProperties": {"type": "object", "properties": _RESULT_FIELDS},
        },
    },
    ("goal_id", "status"),
)

JSON_SCHEMAS: dict[str, tuple[str, dict[str, Any]]] = {
    "status": ("urdaemon/Status", _STATUS),
    "io": ("urdaemon/Io", _IO),
    "events": ("urdaemon/Event", _EVENT),
    "servo_command": ("urdaemon/ServoCommand", _SERVO),
    "goal_feedback": ("urdaemon/GoalFeedback", _FEEDBACK),
    "goal_result": ("urdaemon/GoalResult", _RESULT),
    "cell_goal_result": ("urdaemon/CellGoalResult", _CELL_RESULT),
}
"""Kind name → (schema name, JSON Schema)."""
