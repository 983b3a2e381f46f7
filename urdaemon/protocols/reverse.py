"""Reverse interface (port 50001): the command the External Control script reads each cycle (§4.2).

The robot dials the daemon; the daemon sends one 32-byte frame per command, the robot sends nothing::

    byte   0        4        8       12       16       20       24       28       32
           +--------+--------+--------+--------+--------+--------+--------+--------+
           | timeout|   f1   |   f2   |   f3   |   f4   |   f5   |   f6   |  mode  |
           +--------+--------+--------+--------+--------+--------+--------+--------+
           int32 big-endian each. timeout: whole ms the robot waits for the *next* frame (≤ 0: forever);
           mode: ControlMode; f1–f6 by mode:
             SERVOJ/SPEEDJ/SPEEDL/POSE/TORQUE  six scaled ints (round(value × 1e6))
             FORWARD                           f1 = TrajectoryAction, f2 = point count (raw), f3–f6 = 0
             FREEDRIVE                         f1 = FreedriveAction (raw), f2–f6 = 0
             IDLE, STOPPED                     all zero (STOPPED's timeout is always 100 ms)

What the script does with each frame is §5.4/§5.5: a changed mode switches threads, fields 1–6 are
applied for the new mode, and a read that times out halts the whole program.

``ReverseConnection(Side.DAEMON)`` sends the command messages below; bytes it receives are counted and
dropped (urcl ignores them too) up to ``MAX_IGNORED_BYTES``. ``ReverseConnection(Side.ROBOT)`` decodes
every complete frame into the same message type the daemon sent (typed sub-events per mode, carrying the
timeout in seconds), and sends nothing. A frame whose mode or sub-action the daemon cannot send (an unknown
mode, UNINITIALIZED, TOOL_IN_CONTACT, an unknown trajectory or freedrive action) becomes
``UnknownReverseCommand``: the real script does not act on such a value (it does not fail either), so the
fake controller decides what to model.
"""

from __future__ import annotations

import enum
import math
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Final, TypeAlias

from urdaemon.errors import LocalProtocolError
from urdaemon.model import UR_JOINT_COUNT
from urdaemon.protocols._buffer import Side
from urdaemon.protocols._fixed import (
    INT32_MAX,
    MS_PER_S,
    MULT,
    FixedFrameConnection,
    from_ms,
    int32_frame,
    scale_vector,
    to_ms,
)

__all__ = [
    "DEFAULT_COMMAND_TIMEOUT_S",
    "DEFAULT_CONTROL_TIMEOUT_S",
    "DEFAULT_KEEPALIVE_TIMEOUT_S",
    "FRAME",
    "FRAME_BYTES",
    "FRAME_INTS",
    "MAX_IGNORED_BYTES",
    "MAX_REALTIME_TIMEOUT_S",
    "NON_REALTIME_MODES",
    "PROTOCOL",
    "REALTIME_MODES",
    "REVERSE_PORT",
    "STOPPED_TIMEOUT_S",
    "ControlMode",
    "FreedriveAction",
    "FreedriveControl",
    "Idle",
    "Pose",
    "ReverseCommand",
    "ReverseConnection",
    "ReverseEvent",
    "ServoJ",
    "SpeedJ",
    "SpeedL",
    "Stopped",
    "Torque",
    "TrajectoryAction",
    "TrajectoryControl",
    "UnknownReverseCommand",
    "clamp_timeout",
    "decode_reverse_command",
    "encode_reverse_command",
    "step_time_for_frequency",
]

PROTOCOL: Final = "reverse"
REVERSE_PORT: Final = 50001
"""The reverse interface's usual port, on the daemon's host (§0; the control script is told which)."""

FRAME_INTS: Final = 8
"""int32 per frame: timeout, six fields, mode (§4.1)."""
FRAME_BYTES: Final = 4 * FRAME_INTS
FRAME: Final = int32_frame(FRAME_INTS)
"""The precompiled 32-byte frame struct."""

JOINTS: Final = UR_JOINT_COUNT

STOPPED_TIMEOUT_S: Final = 0.1
"""Timeout field of every STOPPED frame, s: urcl writes a fixed 100 ms (§4.2)."""
MAX_REALTIME_TIMEOUT_S: Final = 0.2
"""Upper clamp of realtime-mode timeouts, s (urcl ``MAX_RT_RECEIVE_TIMEOUT_MS``; §4.2)."""
DEFAULT_COMMAND_TIMEOUT_S: Final = 0.02
"""urcl's default timeout of a joint/Cartesian command, s (§4.2)."""
DEFAULT_CONTROL_TIMEOUT_S: Final = 0.2
"""urcl's default timeout of trajectory and freedrive control frames, s (§4.2)."""
DEFAULT_KEEPALIVE_TIMEOUT_S: Final = 1.0
"""urcl's default timeout of an IDLE keepalive, s (§4.2)."""
MAX_IGNORED_BYTES: Final = 4096
"""Bytes the daemon side drops before it calls the peer broken, B. The script never writes to this
socket (§4.1), so any byte is unexpected; a small allowance tolerates a stray probe, not a stream."""


class ControlMode(enum.IntEnum):
    """Reverse-frame control mode, index 7 (§4.2 table)."""

    STOPPED = -2
    UNINITIALIZED = -1  # script start value, never sent
    IDLE = 0
    SERVOJ = 1
    SPEEDJ = 2
    FORWARD = 3
    SPEEDL = 4
    POSE = 5
    FREEDRIVE = 6
    TOOL_IN_CONTACT = 7  # script-internal, never sent
    TORQUE = 8


REALTIME_MODES: Final = frozenset(
    {ControlMode.SERVOJ, ControlMode.SPEEDJ, ControlMode.SPEEDL, ControlMode.POSE, ControlMode.TORQUE}
)
"""Modes whose timeout urcl clamps to [step time, 200 ms] (§4.2)."""
NON_REALTIME_MODES: Final = frozenset({ControlMode.IDLE, ControlMode.FORWARD, ControlMode.FREEDRIVE})
"""Modes whose timeout may be 0 (block) but not between 0 and one step (§4.2)."""


class TrajectoryAction(enum.IntEnum):
    """FORWARD-mode action in field 1 (§4.2 trajectory control)."""

    CANCEL = -1
    NOOP = 0
    START = 1
    STREAM_START = 2
    STREAM_END = 3


class FreedriveAction(enum.IntEnum):
    """FREEDRIVE-mode action in field 1 (§4.2)."""

    STOP = -1
    NOOP = 0
    START = 1


# -- messages (sent by the daemon, decoded by the robot) ---------------------------------------------


@dataclass(frozen=True, slots=True)
class ServoJ:
    """SERVOJ: joint position setpoint [rad]; ``timeout`` [s] bounds the wait for the next frame."""

    positions: tuple[float, ...]
    timeout: float = DEFAULT_COMMAND_TIMEOUT_S


@dataclass(frozen=True, slots=True)
class SpeedJ:
    """SPEEDJ: joint velocities [rad/s]; ``timeout`` [s] bounds the wait for the next frame."""

    velocities: tuple[float, ...]
    timeout: float = DEFAULT_COMMAND_TIMEOUT_S


@dataclass(frozen=True, slots=True)
class SpeedL:
    """SPEEDL: TCP twist [m/s, rad/s]; ``timeout`` [s] bounds the wait for the next frame."""

    twist: tuple[float, ...]
    timeout: float = DEFAULT_COMMAND_TIMEOUT_S


@dataclass(frozen=True, slots=True)
class Pose:
    """POSE: TCP pose setpoint [m, rotation vector rad], solved by IK on the robot; ``timeout`` [s]."""

    pose: tuple[float, ...]
    timeout: float = DEFAULT_COMMAND_TIMEOUT_S


@dataclass(frozen=True, slots=True)
class Torque:
    """TORQUE: joint torques after gravity compensation [Nm]; ``timeout`` [s] (PolyScope ≥ 5.23 / 10.11)."""

    torques: tuple[float, ...]
    timeout: float = DEFAULT_COMMAND_TIMEOUT_S


@dataclass(frozen=True, slots=True)
class Idle:
    """IDLE keepalive: no motion, fields 1–6 sent as zeros; ``timeout`` [s] bounds the wait for the next."""

    timeout: float = DEFAULT_KEEPALIVE_TIMEOUT_S


@dataclass(frozen=True, slots=True)
class Stopped:
    """STOPPED: ends the script's main loop cleanly (hand back control); timeout field fixed at 100 ms."""


@dataclass(frozen=True, slots=True)
class TrajectoryControl:
    """FORWARD: start/stream/cancel a trajectory on 50003 or keep it alive (NOOP); ``timeout`` [s].

    ``point_count``: START = points that will follow, STREAM_END/CANCEL = points written since
    STREAM_START (0 for a finite CANCEL); NOOP/STREAM_START send 0.
    """

    action: TrajectoryAction
    point_count: int = 0
    timeout: float = DEFAULT_CONTROL_TIMEOUT_S


@dataclass(frozen=True, slots=True)
class FreedriveControl:
    """FREEDRIVE: start, keep (NOOP) or stop freedrive on the robot; ``timeout`` [s]."""

    action: FreedriveAction
    timeout: float = DEFAULT_CONTROL_TIMEOUT_S


@dataclass(frozen=True, slots=True)
class UnknownReverseCommand:
    """(ROBOT side) a frame whose mode or sub-action the daemon never sends; fields 1–6 raw."""

    timeout: float
    mode: int
    fields: tuple[int, ...]


ReverseCommand: TypeAlias = (
    ServoJ | SpeedJ | SpeedL | Pose | Torque | Idle | Stopped | TrajectoryControl | FreedriveControl
)
"""A message the daemon side sends (and the robot side decodes back)."""
ReverseEvent: TypeAlias = ReverseCommand | UnknownReverseCommand
"""An event of the robot side: one per complete frame."""


# -- timeouts ------------------------------------------------------------------------------------------


def step_time_for_frequency(frequency_hz: float) -> float:
    """urcl's step time for an RTDE frequency: ⌊1000 / f⌋ whole ms, in s (2 ms at 500 Hz, 8 ms at 125 Hz)."""
    return math.floor(MS_PER_S / frequency_hz) / MS_PER_S


def clamp_timeout(mode: ControlMode, timeout: float, step_time: float) -> float:
    """The timeout [s] urcl would send for ``mode`` given the robot step time [s] (§4.2 timeout rules).

    Realtime modes: clamped to [step, 200 ms] (0 and negatives become one step). Non-realtime modes:
    ≤ 0 is kept (the robot blocks), 0 < t < step becomes one step. STOPPED: always 100 ms.
    UNINITIALIZED and TOOL_IN_CONTACT are never sent: LocalProtocolError.
    """
    mode = ControlMode(mode)
    if mode is ControlMode.STOPPED:
        return STOPPED_TIMEOUT_S
    ms = to_ms(timeout, PROTOCOL)
    step_ms = to_ms(step_time, PROTOCOL, "step_time")
    if mode in REALTIME_MODES:
        return from_ms(min(max(ms, step_ms), round(MAX_REALTIME_TIMEOUT_S * MS_PER_S)))
    if mode in NON_REALTIME_MODES:
        return from_ms(step_ms if 0 < ms < step_ms else ms)
    raise LocalProtocolError(f"{PROTOCOL}: mode {mode.name} is never sent", protocol=PROTOCOL)


# -- encoding (DAEMON side) ----------------------------------------------------------------------------


def _refuse(message: object, reason: str) -> LocalProtocolError:
    return LocalProtocolError(f"{PROTOCOL}: cannot send {message!r}: {reason}", protocol=PROTOCOL)


def _pack_values(message: object, timeout: float, values: Sequence[float], mode: int, what: str) -> bytes:
    # The 500 Hz path: one unpack, seven round() calls, one precompiled pack. Bad input (wrong length,
    # NaN, inf, out of int32 range) surfaces as one of these exceptions; only then do we pay for the
    # slow, precise diagnosis.
    m = MULT
    try:
        a, b, c, d, e, f = values
        return FRAME.pack(
            round(timeout * MS_PER_S),
            round(a * m),
            round(b * m),
            round(c * m),
            round(d * m),
            round(e * m),
            round(f * m),
            mode,
        )
    except (ValueError, OverflowError, TypeError, struct.error):
        to_ms(timeout, PROTOCOL)
        scale_vector(values, JOINTS, PROTOCOL, what)
        raise _refuse(message, f"{what} or timeout not representable") from None


def _encode_servoj(message: ServoJ) -> bytes:
    return _pack_values(message, message.timeout, message.positions, ControlMode.SERVOJ, "positions")


def encode_servoj(positions: Sequence[float], timeout: float) -> bytes:
    """The SERVOJ frame for ``positions`` without building a message (the 500 Hz path); the same bytes
    as sending ``ServoJ(positions, timeout)``, and the same LocalProtocolError when they cannot be sent."""
    try:
        return _pack_values(None, timeout, positions, ControlMode.SERVOJ, "positions")
    except LocalProtocolError:
        return _encode_servoj(ServoJ(tuple(positions), timeout))  # raises again, naming the message


def _encode_speedj(message: SpeedJ) -> bytes:
    return _pack_values(message, message.timeout, message.velocities, ControlMode.SPEEDJ, "velocities")


def _encode_speedl(message: SpeedL) -> bytes:
    return _pack_values(message, message.timeout, message.twist, ControlMode.SPEEDL, "twist")


def _encode_pose(message: Pose) -> bytes:
    return _pack_values(message, message.timeout, message.pose, ControlMode.POSE, "pose")


def _encode_torque(message: Torque) -> bytes:
    return _pack_values(message, message.timeout, message.torques, ControlMode.TORQUE, "torques")


def _encode_idle(message: Idle) -> bytes:
    # urcl leaves bytes 4–27 of a keepalive uninitialised (§6.8); ours are always zero.
    return FRAME.pack(to_ms(message.timeout, PROTOCOL), 0, 0, 0, 0, 0, 0, ControlMode.IDLE)


_STOPPED_FRAME: Final = FRAME.pack(round(STOPPED_TIMEOUT_S * MS_PER_S), 0, 0, 0, 0, 0, 0, ControlMode.STOPPED)


def _encode_stopped(message: Stopped) -> bytes:
    return _STOPPED_FRAME


_COUNTED_ACTIONS: Final = frozenset(
    {TrajectoryAction.START, TrajectoryAction.STREAM_END, TrajectoryAction.CANCEL}
)
"""Trajectory actions whose field 2 carries a point count (§4.2 trajectory control table)."""


def _encode_trajectory_control(message: TrajectoryControl) -> bytes:
    try:
        action = TrajectoryAction(message.action)
    except ValueError:
        raise _refuse(message, "unknown trajectory action") from None
    count = message.point_count
    if type(count) is not int or not 0 <= count <= INT32_MAX:
        raise _refuse(message, "point_count must be an int in [0, 2**31 - 1]")
    if count and action not in _COUNTED_ACTIONS:
        raise _refuse(message, f"{action.name} carries no point count (send 0)")
    return FRAME.pack(to_ms(message.timeout, PROTOCOL), action, count, 0, 0, 0, 0, ControlMode.FORWARD)


def _encode_freedrive_control(message: FreedriveControl) -> bytes:
    try:
        action = FreedriveAction(message.action)
    except ValueError:
        raise _refuse(message, "unknown freedrive action") from None
    return FRAME.pack(to_ms(message.timeout, PROTOCOL), action, 0, 0, 0, 0, 0, ControlMode.FREEDRIVE)


_ENCODERS: Final[dict[type, Callable[[Any], bytes]]] = {
    ServoJ: _encode_servoj,
    SpeedJ: _encode_speedj,
    SpeedL: _encode_speedl,
    Pose: _encode_pose,
    Torque: _encode_torque,
    Idle: _encode_idle,
    Stopped: _encode_stopped,
    TrajectoryControl: _encode_trajectory_control,
    FreedriveControl: _encode_freedrive_control,
}


def encode_reverse_command(message: ReverseCommand) -> bytes:
    """The 32-byte frame of one command; LocalProtocolError if it cannot be represented."""
    encode = _ENCODERS.get(type(message))
    if encode is None:
        raise LocalProtocolError(f"{PROTOCOL}: {message!r} is not a reverse command", protocol=PROTOCOL)
    return encode(message)


# -- decoding (ROBOT side) -----------------------------------------------------------------------------

_VALUE_MODES: Final[dict[int, Callable[[tuple[float, ...], float], ReverseCommand]]] = {
    ControlMode.SERVOJ: ServoJ,
    ControlMode.SPEEDJ: SpeedJ,
    ControlMode.SPEEDL: SpeedL,
    ControlMode.POSE: Pose,
    ControlMode.TORQUE: Torque,
}
_TRAJECTORY_ACTIONS: Final = {a.value: a for a in TrajectoryAction}
_FREEDRIVE_ACTIONS: Final = {a.value: a for a in FreedriveAction}


def decode_reverse_command(data: bytes, offset: int = 0) -> ReverseEvent:
    """Decode the frame at ``data[offset:offset + 32]``; never raises for a complete frame."""
    ms, f1, f2, f3, f4, f5, f6, mode = FRAME.unpack_from(data, offset)
    timeout = ms / MS_PER_S
    make = _VALUE_MODES.get(mode)
    if make is not None:
        m = MULT
        return make((f1 / m, f2 / m, f3 / m, f4 / m, f5 / m, f6 / m), timeout)
    if mode == ControlMode.IDLE:
        return Idle(timeout)  # the script ignores fields 1–6 of a keepalive
    if mode == ControlMode.STOPPED:
        return Stopped()  # the loop ends: the timeout is never applied
    if mode == ControlMode.FORWARD and f1 in _TRAJECTORY_ACTIONS:
        action = _TRAJECTORY_ACTIONS[f1]
        return TrajectoryControl(action, f2 if action in _COUNTED_ACTIONS else 0, timeout)
    if mode == ControlMode.FREEDRIVE and f1 in _FREEDRIVE_ACTIONS:
        return FreedriveControl(_FREEDRIVE_ACTIONS[f1], timeout)
    return UnknownReverseCommand(timeout, mode, (f1, f2, f3, f4, f5, f6))


# -- connection ----------------------------------------------------------------------------------------


class ReverseConnection(FixedFrameConnection[ReverseCommand, ReverseEvent]):
    """One reverse-interface connection (§4.2), for either party.

    DAEMON: ``send()`` any ``ReverseCommand``; received bytes yield no events (counted in
    ``ignored_bytes``; more than ``MAX_IGNORED_BYTES`` is a RemoteProtocolError).
    ROBOT: ``receive_data()`` yields one ``ReverseEvent`` per complete 32-byte frame; sends nothing.
    """

    __slots__ = ()

    PROTOCOL = PROTOCOL

    def __init__(self, side: Side) -> None:
        if side is Side.DAEMON:
            super().__init__(
                side,
                receive_size=0,
                decode=decode_reverse_command,
                encoders=_ENCODERS,
                ignore_limit=MAX_IGNORED_BYTES,
            )
        else:
            super().__init__(side, receive_size=FRAME_BYTES, decode=decode_reverse_command, encoders={})
