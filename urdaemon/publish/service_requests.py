"""The request decoders of the robot services (``<cell>/<robot>/service/<name>``, services.py).

Each takes the request's payload and returns what the service's request type of model.py is built
from, or raises ``MessageError`` naming the field; ``request_body`` is the other way, a request as
the message's fields (the client's side).
"""

from __future__ import annotations

import math
from typing import Any

from urdaemon.errors import MessageError
from urdaemon.model import (
    FORCE_MODE_DAMPING,
    FORCE_MODE_GAIN_SCALING,
    FORCE_MODE_TYPE,
    IO_SIZES,
    TOOL_VOLTAGES,
)
from urdaemon.publish import fields
from urdaemon.publish.envelope import decode_message, message_body
from urdaemon.publish.fields import Pose6

__all__ = [
    "MAX_COG_M",
    "MAX_FORCE_MODE",
    "MAX_PAYLOAD_KG",
    "WIRE_NAMES",
    "decode_cycle_stats",
    "decode_dashboard",
    "decode_empty",
    "decode_force_mode",
    "decode_set_io",
    "decode_set_payload",
    "decode_set_tcp",
    "decode_speed_slider",
    "decode_tool_voltage",
    "request_body",
]

MAX_PAYLOAD_KG = 35.0
"""Largest payload mass accepted: above every UR arm's rated payload (UR30: 30 kg)."""
MAX_COG_M = 1.0
"""Largest distance of the payload's centre of gravity from the tool flange along any axis (m)."""
MAX_FORCE_MODE = {"wrench": 1000.0, "limits": 10.0, "task_frame": 10.0}
"""Bounds of force mode's vectors: wrench (N, Nm), limits (m/s, rad/s or m, rad), task frame (m, rad)."""
WIRE_NAMES = {"force_type": "type"}
"""Request fields whose name in the message differs (``ForceModeRequest.force_type`` is ``type``)."""


def decode_empty(payload: bytes | None, what: str) -> None:
    """Check the request of a service that takes no arguments: nothing, an empty payload, ``{}`` or
    ``{"v": 1}``; anything else is refused, so garbage never acts."""
    if payload is None or len(payload) == 0:
        return
    data = decode_message(payload, what)
    fields.allowed(data, f"{what} takes no arguments, but got", set())


def decode_set_tcp(payload: bytes | None) -> Pose6:
    """Decode a set_tcp request: pose [x, y, z, rx, ry, rz] (m, rad), the TCP in the tool0 frame (its
    ranges are checked by the service: cell/config.py ``check_tcp``)."""
    what = "set_tcp"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"pose"})
    if "pose" not in data:
        raise MessageError(f"{what}.pose: missing")
    return fields.pose(data["pose"], f"{what}.pose")


def decode_set_io(payload: bytes | None) -> tuple[str, int, float | bool]:
    """Decode a set_io request: kind, pin, value (a number for ``analog``, else true or false)."""
    what = "set_io"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"kind", "pin", "value"})
    kind, pin, value = data.get("kind"), data.get("pin"), data.get("value")
    if not isinstance(kind, str):
        raise MessageError(f"{what}.kind: expected one of {', '.join(IO_SIZES)}")
    if isinstance(pin, bool) or not isinstance(pin, int):
        raise MessageError(f"{what}.pin: expected an integer")
    if kind == "analog":
        return kind, pin, fields.number(value, f"{what}.value")
    if kind in IO_SIZES and not isinstance(value, bool):
        raise MessageError(f"{what}.value: a {kind} output takes true or false, got {fields.shown(value)}")
    if isinstance(value, bool):
        return kind, pin, value
    return kind, pin, fields.number(value, f"{what}.value")


def decode_set_payload(payload: bytes | None) -> tuple[float, tuple[float, float, float]]:
    """Decode a set_payload request: mass (kg), cog [x, y, z] (m)."""
    what = "set_payload"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"mass", "cog"})
    mass = fields.number(data.get("mass"), f"{what}.mass")
    if not math.isfinite(mass) or mass < 0:
        raise MessageError(f"{what}.mass: must be a finite number ≥ 0, got {mass}")
    fields.within(mass, f"{what}.mass (kg)", 0.0, MAX_PAYLOAD_KG)
    cog = fields.numbers(data.get("cog", [0.0, 0.0, 0.0]), f"{what}.cog")
    if len(cog) != 3 or not all(math.isfinite(c) for c in cog):
        raise MessageError(f"{what}.cog: expected three finite numbers")
    for i, c in enumerate(cog):
        fields.within(c, f"{what}.cog[{i}] (m)", -MAX_COG_M, MAX_COG_M)
    return mass, (cog[0], cog[1], cog[2])


def decode_dashboard(payload: bytes | None) -> str:
    """Decode a dashboard request: command (one line, e.g. ``power on``)."""
    what = "dashboard"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"command"})
    command = data.get("command")
    if not isinstance(command, str) or not command.strip():
        raise MessageError(f'{what}.command: expected a dashboard command line, e.g. "power on"')
    if not command.isprintable() or len(command) > 1024:
        raise MessageError(f"{what}.command: must be one line of at most 1024 printable characters")
    return command.strip()


def decode_tool_voltage(payload: bytes | None) -> int:
    """Decode a set_tool_voltage request: volts (0, 12 or 24)."""
    what = "set_tool_voltage"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"volts"})
    volts = data.get("volts")
    if isinstance(volts, bool) or volts not in TOOL_VOLTAGES:
        raise MessageError(
            f"{what}.volts: must be {', '.join(map(str, TOOL_VOLTAGES[:-1]))} or {TOOL_VOLTAGES[-1]}"
        )
    return int(volts)


def decode_force_mode(payload: bytes | None) -> dict[str, Any]:
    """Decode a start_force_mode request into the fields of the script command (docs/protocols.md §4.5)."""
    what = "start_force_mode"
    data = decode_message(payload, what)
    fields.allowed(
        data, what, {"task_frame", "selection", "wrench", "type", "limits", "damping", "gain_scaling"}
    )
    decoded: dict[str, Any] = {}
    for key in ("task_frame", "wrench", "limits"):
        values = fields.numbers(data.get(key), f"{what}.{key}")
        if len(values) != 6 or not all(math.isfinite(v) for v in values):
            raise MessageError(f"{what}.{key}: expected six finite numbers")
        bound = MAX_FORCE_MODE[key]
        low = 0.0 if key == "limits" else -bound
        for i, v in enumerate(values):
            fields.within(v, f"{what}.{key}[{i}]", low, bound)
        decoded[key] = values
    selection = data.get("selection")
    if (
        not isinstance(selection, list)
        or len(selection) != 6
        or any(v not in (0, 1) or isinstance(v, bool) for v in selection)
    ):
        raise MessageError(f"{what}.selection: expected six 0/1 values")
    decoded["selection"] = tuple(int(v) for v in selection)
    force_type = data.get("type", FORCE_MODE_TYPE)
    if isinstance(force_type, bool) or force_type not in (1, 2, 3):
        raise MessageError(f"{what}.type: must be 1, 2 or 3")
    decoded["force_type"] = int(force_type)
    for key, low, high, default in (
        ("damping", 0.0, 1.0, FORCE_MODE_DAMPING),
        ("gain_scaling", 0.0, 2.0, FORCE_MODE_GAIN_SCALING),
    ):
        value = data.get(key, default)
        decoded[key] = fields.within(fields.number(value, f"{what}.{key}"), f"{what}.{key}", low, high)
    return decoded


def decode_speed_slider(payload: bytes | None) -> float:
    """Decode a set_speed_slider request: fraction in [0, 1]."""
    what = "set_speed_slider"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"fraction"})
    return fields.within(
        fields.number(data.get("fraction"), f"{what}.fraction"), f"{what}.fraction", 0.0, 1.0
    )


def decode_cycle_stats(payload: bytes | None) -> bool:
    """Decode a cycle_stats request: whether to reset the counters after reading them (default no)."""
    what = "cycle_stats"
    if payload is None or len(payload) == 0:
        return False
    data = decode_message(payload, what)
    fields.allowed(data, what, {"reset"})
    return fields.boolean(data, "reset", what)


def request_body(request: object | None) -> dict[str, Any]:
    """A service request (a dataclass of model.py, or None: no arguments) as the message's fields."""
    return {} if request is None else message_body(request, WIRE_NAMES)
