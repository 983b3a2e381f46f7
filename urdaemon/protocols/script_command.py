"""Script command interface (port 50004): one-shot commands in, tool-contact results out (§4.5).

The robot dials the daemon and reads this socket in its own thread with a blocking read (no keepalive,
no timeout). The daemon sends one 112-byte frame per command; the robot sends one int32 when a tool
contact ends::

    index    0        1 … 27
           +--------+---------------------------------------------------------+
           | id raw | arguments by command (table below), then zeros to 27    |
           +--------+---------------------------------------------------------+
    28 big-endian int32. Arguments are scaled ints (round(value × 1e6)) except those marked raw.

    id  command                    arguments (wire indices)
     0  ZeroFtSensor               —
     1  SetPayload                 1 mass kg · 2–4 CoG m
     2  SetToolVoltage             1 volts (0, 12, 24)
     3  StartForceMode             1–6 task frame · 7–12 selection 0/1 · 13–18 wrench · 19 type 1–3 ·
                                   20–25 limits · 26 damping [0, 1] · 27 gain scaling [0, 2]
     4  EndForceMode               —
     5  StartToolContact           —
     6  EndToolContact             —
     7  SetFrictionCompensation    1 enabled 0/1 raw
     8  FtRtdeInputEnable          1 enabled 0/1 raw · 2 sensor mass kg · 3–5 offset m · 6–8 CoG m
     9  SetGravity                 1–3 gravity vector m/s²
    10  SetTcpOffset               1–6 pose in the flange frame
    11  SetFrictionScales          1–6 viscous · 7–12 Coulomb, each in [0, 1]
    12  SetTargetPayload           1 mass · 2–4 CoG · 5–10 inertia Ixx Iyy Izz Ixy Ixz Iyz · 11 transition s

    Robot → daemon: one int32, 0 = contact detected (SUCCESS), 1 = CANCELED.

``ScriptCommandConnection(Side.DAEMON)`` sends the command dataclasses and refuses values the reference
rules out (LocalProtocolError); it yields ``ToolContactResult`` events. A result other than 0 or 1 is a
``RemoteProtocolError``: the script only sends those two and the 4-byte stream cannot resynchronise.

``ScriptCommandConnection(Side.ROBOT)`` decodes each frame into the same dataclass, or
``UnknownScriptCommand`` for an id the script does not know (it ignores such a command). It reports
values as read, without range checks (a URScript builtin would raise or act on them; the fake
decides); the one RemoteProtocolError is a fractional value where the field is a whole number (tool
voltage, force-mode type, selection vector). It sends ``ToolContactResultMessage``.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Final, TypeAlias

from urdaemon.errors import LocalProtocolError, RemoteProtocolError
from urdaemon.model import FORCE_MODE_DAMPING, FORCE_MODE_GAIN_SCALING
from urdaemon.model import TOOL_VOLTAGES as MODEL_TOOL_VOLTAGES
from urdaemon.protocols._buffer import Side
from urdaemon.protocols._fixed import (
    INT32,
    MULT,
    FixedFrameConnection,
    int32_frame,
    is_finite,
    scale,
    scale_vector,
    unscale_integral,
)

__all__ = [
    "DEFAULT_FORCE_MODE_DAMPING",
    "DEFAULT_FORCE_MODE_GAIN_SCALING",
    "FORCE_MODE_TYPES",
    "FRAME",
    "FRAME_BYTES",
    "FRAME_INTS",
    "PROTOCOL",
    "RESULT_BYTES",
    "SCRIPT_COMMAND_PORT",
    "TOOL_VOLTAGES",
    "EndForceMode",
    "EndToolContact",
    "FtRtdeInputEnable",
    "ScriptCommand",
    "ScriptCommandConnection",
    "ScriptCommandEvent",
    "ScriptCommandId",
    "SetFrictionCompensation",
    "SetFrictionScales",
    "SetGravity",
    "SetPayload",
    "SetTargetPayload",
    "SetTcpOffset",
    "SetToolVoltage",
    "StartForceMode",
    "StartToolContact",
    "ToolContactResult",
    "ToolContactResultCode",
    "ToolContactResultMessage",
    "UnknownScriptCommand",
    "ZeroFtSensor",
    "decode_script_command",
    "encode_script_command",
]

PROTOCOL: Final = "script_command"
SCRIPT_COMMAND_PORT: Final = 50004
"""The script command interface's usual port, on the daemon's host (§0)."""

FRAME_INTS: Final = 28
"""int32 per command: the id and 27 argument slots (§4.5)."""
FRAME_BYTES: Final = 4 * FRAME_INTS
FRAME: Final = int32_frame(FRAME_INTS)
"""The precompiled 112-byte command struct."""
RESULT_BYTES: Final = 4
"""One int32 tool-contact result per message (§4.5)."""

TOOL_VOLTAGES: Final = MODEL_TOOL_VOLTAGES
"""Tool supply voltages the controller offers, V (§4.5; model.py's ``TOOL_VOLTAGES``)."""
FORCE_MODE_TYPES: Final = (1, 2, 3)
"""URScript force_mode ``type`` values (§4.5)."""
DEFAULT_FORCE_MODE_DAMPING: Final = FORCE_MODE_DAMPING
"""urcl's default force-mode damping, in [0, 1] (§4.5; URScript's, model.py's ``FORCE_MODE_DAMPING``)."""
DEFAULT_FORCE_MODE_GAIN_SCALING: Final = FORCE_MODE_GAIN_SCALING
"""urcl's default force-mode gain scaling, in [0, 2]; e-Series only (§4.5; model.py's)."""
MAX_DAMPING: Final = 1.0
MAX_GAIN_SCALING: Final = 2.0
MAX_FRICTION_SCALE: Final = 1.0


class ScriptCommandId(enum.IntEnum):
    """Command id, raw int at index 0 (§4.5)."""

    ZERO_FTSENSOR = 0
    SET_PAYLOAD = 1
    SET_TOOL_VOLTAGE = 2
    START_FORCE_MODE = 3
    END_FORCE_MODE = 4
    START_TOOL_CONTACT = 5
    END_TOOL_CONTACT = 6
    SET_FRICTION_COMPENSATION = 7  # deprecated; PolyScope ≥ 5.23.0 / ≥ 10.10.0
    FT_RTDE_INPUT_ENABLE = 8
    SET_GRAVITY = 9
    SET_TCP_OFFSET = 10
    SET_FRICTION_SCALES = 11  # PolyScope ≥ 5.25.1 / ≥ 10.12.1
    SET_TARGET_PAYLOAD = 12


class ToolContactResultCode(enum.IntEnum):
    """How a tool contact ended, the int32 the robot sends on 50004 (§4.5)."""

    SUCCESS = 0  # contact detected
    CANCELED = 1  # END_TOOL_CONTACT arrived before any contact


# -- commands (sent by the daemon, decoded by the robot) -----------------------------------------------


@dataclass(frozen=True, slots=True)
class ZeroFtSensor:
    """Zero the tool force/torque sensor (e-Series)."""


@dataclass(frozen=True, slots=True)
class SetPayload:
    """Set the payload mass [kg] and centre of gravity [m, flange frame]."""

    mass: float
    cog: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class SetToolVoltage:
    """Set the tool supply voltage [V]: 0, 12 or 24."""

    volts: int


@dataclass(frozen=True, slots=True)
class StartForceMode:
    """Enter force mode: URScript ``force_mode(task_frame, selection, wrench, force_type, limits)``.

    ``selection``: 1 = compliant axis, 0 = not; ``force_type`` 1–3; ``damping`` in [0, 1];
    ``gain_scaling`` in [0, 2] (applied on e-Series only).
    """

    task_frame: tuple[float, ...]
    selection: tuple[int, ...]
    wrench: tuple[float, ...]
    force_type: int
    limits: tuple[float, ...]
    damping: float = DEFAULT_FORCE_MODE_DAMPING
    gain_scaling: float = DEFAULT_FORCE_MODE_GAIN_SCALING


@dataclass(frozen=True, slots=True)
class EndForceMode:
    """Leave force mode."""


@dataclass(frozen=True, slots=True)
class StartToolContact:
    """Arm tool-contact detection; the robot answers with a tool-contact result (e-Series)."""


@dataclass(frozen=True, slots=True)
class EndToolContact:
    """Disarm tool-contact detection; answered with CANCELED if no contact happened."""


@dataclass(frozen=True, slots=True)
class SetFrictionCompensation:
    """Switch legacy friction compensation of torque mode on or off (deprecated)."""

    enabled: bool


@dataclass(frozen=True, slots=True)
class FtRtdeInputEnable:
    """Use an external F/T sensor fed over RTDE: mass [kg], measuring offset [m], CoG [m]."""

    enabled: bool
    sensor_mass: float
    sensor_offset: tuple[float, ...]
    sensor_cog: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class SetGravity:
    """Set the gravity vector [m/s²] (URScript convention: pointing up, e.g. (0, 0, 9.82) floor-mounted).

    The reference marks the direction convention unverified (§4.5); the codec sends the vector as given.
    """

    gravity: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class SetTcpOffset:
    """Set the TCP as a pose [m, rotation vector rad] in the flange frame."""

    pose: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class SetFrictionScales:
    """Set torque-mode friction scales per joint, viscous and Coulomb, each in [0, 1]."""

    viscous: tuple[float, ...]
    coulomb: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class SetTargetPayload:
    """Set payload mass [kg], CoG [m], inertia [kg m²: Ixx Iyy Izz Ixy Ixz Iyz] over ``transition_time`` s."""

    mass: float
    cog: tuple[float, ...]
    inertia: tuple[float, ...]
    transition_time: float = 0.0


@dataclass(frozen=True, slots=True)
class UnknownScriptCommand:
    """(ROBOT side) a command id the script does not know; arguments as the 27 raw ints."""

    command_id: int
    ints: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class ToolContactResultMessage:
    """(ROBOT side sends) how the armed tool contact ended."""

    code: ToolContactResultCode


@dataclass(frozen=True, slots=True)
class ToolContactResult:
    """(DAEMON side receives) contact detected (SUCCESS) or tool contact ended without one (CANCELED)."""

    code: ToolContactResultCode


ScriptCommand: TypeAlias = (
    ZeroFtSensor
    | SetPayload
    | SetToolVoltage
    | StartForceMode
    | EndForceMode
    | StartToolContact
    | EndToolContact
    | SetFrictionCompensation
    | FtRtdeInputEnable
    | SetGravity
    | SetTcpOffset
    | SetFrictionScales
    | SetTargetPayload
)
"""A command the daemon side sends (and the robot side decodes back)."""
ScriptCommandEvent: TypeAlias = ScriptCommand | UnknownScriptCommand | ToolContactResult
"""An event of either side: commands on the robot side, results on the daemon side."""


# -- layout: one table drives both encoding and decoding ------------------------------------------------


class _Kind(enum.Enum):
    REAL = "real"  # one scaled float
    WHOLE = "whole"  # one scaled whole number (int field)
    FLAG = "flag"  # one raw 0/1 (bool field; the script tests != 0)


@dataclass(frozen=True, slots=True)
class _Field:
    name: str
    kind: _Kind
    count: int  # 1: a scalar field; n > 1: a tuple field of n values


def _real(name: str, count: int = 1) -> _Field:
    return _Field(name, _Kind.REAL, count)


_LAYOUT: Final[dict[type, tuple[ScriptCommandId, tuple[_Field, ...]]]] = {
    ZeroFtSensor: (ScriptCommandId.ZERO_FTSENSOR, ()),
    SetPayload: (ScriptCommandId.SET_PAYLOAD, (_real("mass"), _real("cog", 3))),
    SetToolVoltage: (ScriptCommandId.SET_TOOL_VOLTAGE, (_Field("volts", _Kind.WHOLE, 1),)),
    StartForceMode: (
        ScriptCommandId.START_FORCE_MODE,
        (
            _real("task_frame", 6),
            _Field("selection", _Kind.WHOLE, 6),
            _real("wrench", 6),
            _Field("force_type", _Kind.WHOLE, 1),
            _real("limits", 6),
            _real("damping"),
            _real("gain_scaling"),
        ),
    ),
    EndForceMode: (ScriptCommandId.END_FORCE_MODE, ()),
    StartToolContact: (ScriptCommandId.START_TOOL_CONTACT, ()),
    EndToolContact: (ScriptCommandId.END_TOOL_CONTACT, ()),
    SetFrictionCompensation: (ScriptCommandId.SET_FRICTION_COMPENSATION, (_Field("enabled", _Kind.FLAG, 1),)),
    FtRtdeInputEnable: (
        ScriptCommandId.FT_RTDE_INPUT_ENABLE,
        (
            _Field("enabled", _Kind.FLAG, 1),
            _real("sensor_mass"),
            _real("sensor_offset", 3),
            _real("sensor_cog", 3),
        ),
    ),
    SetGravity: (ScriptCommandId.SET_GRAVITY, (_real("gravity", 3),)),
    SetTcpOffset: (ScriptCommandId.SET_TCP_OFFSET, (_real("pose", 6),)),
    SetFrictionScales: (ScriptCommandId.SET_FRICTION_SCALES, (_real("viscous", 6), _real("coulomb", 6))),
    SetTargetPayload: (
        ScriptCommandId.SET_TARGET_PAYLOAD,
        (_real("mass"), _real("cog", 3), _real("inertia", 6), _real("transition_time")),
    ),
}
"""Per command: its id and its argument fields in wire order (= dataclass field order)."""

_BY_ID: Final[dict[int, tuple[type, tuple[_Field, ...]]]] = {
    command_id: (cls, fields) for cls, (command_id, fields) in _LAYOUT.items()
}


# -- encoding ------------------------------------------------------------------------------------------


def _refuse(message: object, reason: str) -> LocalProtocolError:
    return LocalProtocolError(f"{PROTOCOL}: cannot send {message!r}: {reason}", protocol=PROTOCOL)


def _in_range(value: float, low: float, high: float) -> bool:
    return is_finite(value) and low <= value <= high


def _whole_in(value: object, allowed: tuple[int, ...]) -> bool:
    return type(value) in (int, bool) and value in allowed


def _problem(message: ScriptCommand) -> str | None:
    """Why the reference rules this command out, or None; the range checks urcl and URScript apply."""
    match message:
        case SetToolVoltage(volts=volts) if not _whole_in(volts, TOOL_VOLTAGES):
            return f"volts must be one of {TOOL_VOLTAGES}"
        case StartForceMode() if not _whole_in(message.force_type, FORCE_MODE_TYPES):
            return f"force_type must be one of {FORCE_MODE_TYPES}"
        case StartForceMode() if not all(_whole_in(s, (0, 1)) for s in message.selection):
            return "selection entries must be 0 or 1"
        case StartForceMode() if not _in_range(message.damping, 0.0, MAX_DAMPING):
            return f"damping must be within [0, {MAX_DAMPING}]"
        case StartForceMode() if not _in_range(message.gain_scaling, 0.0, MAX_GAIN_SCALING):
            return f"gain_scaling must be within [0, {MAX_GAIN_SCALING}]"
        case SetFrictionScales() if not all(
            _in_range(v, 0.0, MAX_FRICTION_SCALE) for v in (*message.viscous, *message.coulomb)
        ):
            # urcl clamps silently; we refuse instead so that a caller's mistake is not hidden
            return f"friction scales must be within [0, {MAX_FRICTION_SCALE}]"
        case SetPayload(mass=mass) | SetTargetPayload(mass=mass) if not _in_range(mass, 0.0, float("inf")):
            return "mass must be finite and ≥ 0"
        case FtRtdeInputEnable(sensor_mass=mass) if not _in_range(mass, 0.0, float("inf")):
            return "sensor_mass must be finite and ≥ 0"
        case SetTargetPayload(transition_time=t) if not _in_range(t, 0.0, float("inf")):
            return "transition_time must be finite and ≥ 0"
    return None


def _field_ints(message: object, field: _Field) -> list[int]:
    value = getattr(message, field.name)
    if field.kind is _Kind.FLAG:
        return [1 if value else 0]
    if field.count == 1:
        return [scale(value, PROTOCOL, field.name)]
    return scale_vector(value, field.count, PROTOCOL, field.name)


def encode_script_command(message: ScriptCommand) -> bytes:
    """The 112-byte frame of one command; LocalProtocolError if it is invalid or cannot be represented."""
    layout = _LAYOUT.get(type(message))
    if layout is None:
        raise LocalProtocolError(f"{PROTOCOL}: {message!r} is not a script command", protocol=PROTOCOL)
    try:
        reason = _problem(message)
    except TypeError:  # e.g. a vector that is not a sequence
        reason = "an argument has the wrong type"
    if reason is not None:
        raise _refuse(message, reason)
    command_id, fields = layout
    ints = [int(command_id)]
    for field in fields:
        ints += _field_ints(message, field)
    ints += [0] * (FRAME_INTS - len(ints))  # zero-fill: never leave garbage in unused slots
    return FRAME.pack(*ints)


def _encode_result(message: ToolContactResultMessage) -> bytes:
    try:
        return INT32.pack(ToolContactResultCode(message.code))
    except ValueError:
        raise _refuse(message, "unknown tool-contact result code") from None


_COMMAND_ENCODERS: Final[dict[type, Callable[[Any], bytes]]] = dict.fromkeys(_LAYOUT, encode_script_command)
_RESULT_ENCODERS: Final[dict[type, Callable[[Any], bytes]]] = {ToolContactResultMessage: _encode_result}


# -- decoding ------------------------------------------------------------------------------------------


def _whole(raw: int, name: str) -> int:
    value = unscale_integral(raw)
    if value is None:
        raise RemoteProtocolError(
            f"{PROTOCOL}: {name} = {raw / MULT} is not a whole number", protocol=PROTOCOL
        )
    return value


def _field_value(ints: tuple[int, ...], at: int, field: _Field) -> object:
    if field.kind is _Kind.FLAG:
        return ints[at] != 0  # the script tests the raw value against 0
    if field.kind is _Kind.WHOLE:
        values: tuple[object, ...] = tuple(_whole(r, field.name) for r in ints[at : at + field.count])
    else:
        values = tuple([r / MULT for r in ints[at : at + field.count]])
    return values[0] if field.count == 1 else values


def decode_script_command(data: bytes, offset: int = 0) -> ScriptCommand | UnknownScriptCommand:
    """Decode the command at ``data[offset:offset + 112]``; RemoteProtocolError only for a fraction
    where the field is a whole number."""
    ints: tuple[int, ...] = FRAME.unpack_from(data, offset)
    known = _BY_ID.get(ints[0])
    if known is None:
        return UnknownScriptCommand(ints[0], ints[1:])  # the script ignores an unknown id
    cls, fields = known
    at = 1
    values = []
    for field in fields:
        values.append(_field_value(ints, at, field))
        at += field.count
    command: ScriptCommand = cls(*values)
    return command


_RESULT_CODES: Final = {c.value: c for c in ToolContactResultCode}


def _decode_result(data: bytes, offset: int) -> ToolContactResult:
    (value,) = INT32.unpack_from(data, offset)
    code = _RESULT_CODES.get(value)
    if code is None:
        raise RemoteProtocolError(f"{PROTOCOL}: unknown tool-contact result {value}", protocol=PROTOCOL)
    return ToolContactResult(code)


# -- connection ----------------------------------------------------------------------------------------


class ScriptCommandConnection(
    FixedFrameConnection[ScriptCommand | ToolContactResultMessage, ScriptCommandEvent]
):
    """One script-command connection (§4.5), for either party.

    DAEMON: ``send(<command>)``; yields ``ToolContactResult`` per 4 received bytes.
    ROBOT: yields a command dataclass or ``UnknownScriptCommand`` per 112 received bytes;
    ``send(ToolContactResultMessage)``.
    """

    __slots__ = ()

    PROTOCOL = PROTOCOL

    def __init__(self, side: Side) -> None:
        if side is Side.DAEMON:
            super().__init__(
                side, receive_size=RESULT_BYTES, decode=_decode_result, encoders=_COMMAND_ENCODERS
            )
        else:
            super().__init__(
                side, receive_size=FRAME_BYTES, decode=decode_script_command, encoders=_RESULT_ENCODERS
            )
