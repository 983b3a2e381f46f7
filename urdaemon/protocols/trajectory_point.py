"""Trajectory point interface (port 50003): motion points in, trajectory results out (docs/protocols.md §4.4).

The robot dials the daemon. The daemon sends one 84-byte frame per point (21 big-endian int32, no
length prefix, no timeout, no mode); the robot answers one int32 when a trajectory ends::

    index   0 … 5     6 … 11          12        13        14          15 … 17   18        19           20
          +---------+---------------+---------+---------+-----------+---------+---------+------------+------+
    motion| target  | via / q_near  | velocity| accel.  | arc mode /| 0       | duration| blend      | type |
          |         | (else 0)      |         |         | has q_near|         |         | radius     | raw  |
          +---------+---------------+---------+---------+-----------+---------+---------+------------+------+
    spline| q       | qd            | qdd (quintic; cubic: 0)                 | segment | spline type| 51   |
          |         |               |                                         | time    | raw 1 / 2  |      |
          +---------+---------------+-----------------------------------------+---------+------------+------+
    Every field is a scaled int (round(value × 1e6); durations and blend radii too) except the two
    marked raw. Robot → daemon: one int32, 0 SUCCESS, 1 CANCELED, 2 FAILURE.

``TrajectoryPointConnection(Side.DAEMON)`` sends ``SplinePoint`` / ``MotionPoint`` and yields
``TrajectoryResult`` events. A result value other than 0, 1 or 2 is a ``RemoteProtocolError``: the
script only ever sends those three (urcl's −1 UNKNOWN is a local placeholder, never on the wire), and
since the stream has no framing beyond "4 bytes", an unexpected value means the peer is not our script
or the stream is out of step, so nothing after it can be trusted.

``TrajectoryPointConnection(Side.ROBOT)`` yields one event per 84-byte frame: a ``SplinePoint`` or
``MotionPoint`` equal to what the daemon sent, or ``UnknownTrajectoryPoint`` for a motion type or spline
type the script does not know (the script skips an unknown motion type silently and answers an unknown
spline type with FAILURE; §5.5); it sends ``TrajectoryResultMessage``. The robot side does not judge
values (negative durations, speeds …): the script either acts on them or fails, and the fake decides.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Final, TypeAlias

from urdaemon.errors import LocalProtocolError, RemoteProtocolError
from urdaemon.model import UR_JOINT_COUNT
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
    "CIRCULAR_TYPES",
    "DEFAULT_ACCELERATION",
    "DEFAULT_VELOCITY",
    "FRAME",
    "FRAME_BYTES",
    "FRAME_INTS",
    "JOINT_TARGET_TYPES",
    "MAX_DURATION_S",
    "OPTIMOVE_TYPES",
    "POSE_TARGET_TYPES",
    "PROTOCOL",
    "RESULT_BYTES",
    "TRAJECTORY_PORT",
    "MotionPoint",
    "MotionType",
    "SplinePoint",
    "SplineType",
    "TrajectoryPoint",
    "TrajectoryPointConnection",
    "TrajectoryPointEvent",
    "TrajectoryResult",
    "TrajectoryResultCode",
    "TrajectoryResultMessage",
    "UnknownTrajectoryPoint",
    "decode_point",
    "encode_point",
]

PROTOCOL: Final = "trajectory_point"
TRAJECTORY_PORT: Final = 50003
"""The trajectory point interface's usual port, on the daemon's host (§0)."""

FRAME_INTS: Final = 21
"""int32 per point: 3 × 6 values + duration + blend/spline type + motion type (§4.4)."""
FRAME_BYTES: Final = 4 * FRAME_INTS
FRAME: Final = int32_frame(FRAME_INTS)
"""The precompiled 84-byte point struct."""
RESULT_BYTES: Final = 4
"""One int32 trajectory result per message (§4.4; urcl expects exactly 4 bytes)."""

JOINTS: Final = UR_JOINT_COUNT
MAX_DURATION_S: Final = 2147.0
"""Longest duration / segment time urcl sends, s (``MAX_GOAL_TIME_``; a scaled int32 tops out at 2147.48)."""
DEFAULT_VELOCITY: Final = 1.05
"""urcl's point-API default velocity, rad/s or m/s (§4.4)."""
DEFAULT_ACCELERATION: Final = 1.4
"""urcl's default acceleration, rad/s² or m/s² (§4.4)."""

_I_DURATION: Final = 18
_I_BLEND: Final = 19  # blend radius, or the raw spline type for SPLINE points
_I_TYPE: Final = 20
_I_FLAG: Final = 14  # arc mode (MOVEC*) or has-q_near (pose targets)


class MotionType(enum.IntEnum):
    """Motion type, raw int at index 20 (§4.4 table)."""

    MOVEJ = 0
    MOVEL = 1
    MOVEP = 2
    MOVEC = 3
    OPTIMOVEJ = 4  # PolyScope ≥ 5.21.0 / ≥ 10.8.0
    OPTIMOVEL = 5
    MOVEJ_POSE = 6
    MOVEL_JOINT = 7
    MOVEP_JOINT = 8
    MOVEC_JOINT = 9
    MOVEC_JOINT_POSE = 10  # via pose, target joints
    MOVEC_POSE_JOINT = 11  # via joints, target pose
    OPTIMOVEJ_POSE = 12
    OPTIMOVEL_JOINT = 13
    SPLINE = 51


class SplineType(enum.IntEnum):
    """Spline interpolation, raw int at index 19 of a SPLINE point (§4.4)."""

    CUBIC = 1
    QUINTIC = 2


JOINT_TARGET_TYPES: Final = frozenset(
    {
        MotionType.MOVEJ,
        MotionType.MOVEL_JOINT,
        MotionType.MOVEP_JOINT,
        MotionType.OPTIMOVEJ,
        MotionType.OPTIMOVEL_JOINT,
    }
)
"""Non-circular motions to a joint target: indices 6–11 and 14 are zero."""
POSE_TARGET_TYPES: Final = frozenset(
    {
        MotionType.MOVEL,
        MotionType.MOVEP,
        MotionType.OPTIMOVEL,
        MotionType.MOVEJ_POSE,
        MotionType.OPTIMOVEJ_POSE,
    }
)
"""Non-circular motions to a pose: indices 6–11 may carry q_near (flag at 14). urcl sends q_near for all
of these; the script only uses it for MOVEJ_POSE and OPTIMOVEJ_POSE (IK seed)."""
CIRCULAR_TYPES: Final = frozenset(
    {MotionType.MOVEC, MotionType.MOVEC_JOINT, MotionType.MOVEC_JOINT_POSE, MotionType.MOVEC_POSE_JOINT}
)
"""movec variants: indices 6–11 are the via point, index 14 the arc mode."""
OPTIMOVE_TYPES: Final = frozenset(
    {MotionType.OPTIMOVEJ, MotionType.OPTIMOVEL, MotionType.OPTIMOVEJ_POSE, MotionType.OPTIMOVEL_JOINT}
)
"""Motions whose velocity and acceleration are fractions in (0, 1] (§4.4)."""
ARC_MODES: Final = (0, 1)
"""movec ``mode``: 0 unconstrained, 1 fixed orientation (URScript movec)."""


class TrajectoryResultCode(enum.IntEnum):
    """How a trajectory ended, the int32 the robot sends on 50003 (§4.4)."""

    SUCCESS = 0
    CANCELED = 1
    FAILURE = 2


# -- points (sent by the daemon, decoded by the robot) -------------------------------------------------


@dataclass(frozen=True, slots=True)
class SplinePoint:
    """One SPLINE point: joint positions [rad] reached ``segment_time`` [s] after the previous point.

    Cubic when ``accelerations`` is None, quintic otherwise; ``velocities`` None is sent as zeros (the
    robot side then reports zeros), as urcl's positions-only trajectories should be (§4.4, §6.8).
    """

    positions: tuple[float, ...]
    velocities: tuple[float, ...] | None
    accelerations: tuple[float, ...] | None
    segment_time: float


@dataclass(frozen=True, slots=True)
class MotionPoint:
    """One robot-planned motion (movej/movel/movep/movec/optimove*) to ``target`` (§4.4 table).

    ``via_or_qnear``: MOVEC*: the via point (required); pose targets: optional q_near IK seed [rad];
    joint targets: None. ``velocity``/``acceleration``: rad/s(²) or m/s(²), fractions in (0, 1] for
    OPTIMOVE*. ``duration`` [s] > 0 overrides them (ignored by movep/optimove). ``arc_mode``: movec only.
    """

    motion_type: MotionType
    target: tuple[float, ...]
    via_or_qnear: tuple[float, ...] | None = None
    velocity: float = DEFAULT_VELOCITY
    acceleration: float = DEFAULT_ACCELERATION
    blend_radius: float = 0.0
    duration: float = 0.0
    arc_mode: int = 0


@dataclass(frozen=True, slots=True)
class UnknownTrajectoryPoint:
    """(ROBOT side) a point whose motion type, or spline type, the script does not know; all 21 raw ints."""

    motion_type: int
    ints: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class TrajectoryResultMessage:
    """(ROBOT side sends) how the trajectory ended."""

    code: TrajectoryResultCode


@dataclass(frozen=True, slots=True)
class TrajectoryResult:
    """(DAEMON side receives) the robot finished, cancelled or failed the trajectory."""

    result: TrajectoryResultCode


TrajectoryPoint: TypeAlias = SplinePoint | MotionPoint
"""A point the daemon side sends (and the robot side decodes back)."""
TrajectoryPointEvent: TypeAlias = SplinePoint | MotionPoint | UnknownTrajectoryPoint | TrajectoryResult
"""An event of either side: points on the robot side, results on the daemon side."""


# -- encoding ------------------------------------------------------------------------------------------


def _refuse(message: object, reason: str) -> LocalProtocolError:
    return LocalProtocolError(f"{PROTOCOL}: cannot send {message!r}: {reason}", protocol=PROTOCOL)


def _vector(values: Sequence[float] | None, what: str) -> list[int]:
    if values is None:
        return [0] * JOINTS
    return scale_vector(values, JOINTS, PROTOCOL, what)


def _duration(message: object, seconds: float, what: str) -> int:
    if not is_finite(seconds) or not 0.0 <= seconds <= MAX_DURATION_S:
        raise _refuse(message, f"{what} must be within [0, {MAX_DURATION_S}] s")
    return scale(seconds, PROTOCOL, what)


def _encode_spline(message: SplinePoint) -> bytes:
    spline = SplineType.CUBIC if message.accelerations is None else SplineType.QUINTIC
    if message.positions is None:
        raise _refuse(message, "positions are required")
    ints = _vector(message.positions, "positions")
    ints += _vector(message.velocities, "velocities")
    ints += _vector(message.accelerations, "accelerations")
    ints += (_duration(message, message.segment_time, "segment_time"), spline, MotionType.SPLINE)
    return FRAME.pack(*ints)


def _motion_type(message: MotionPoint) -> MotionType:
    try:
        kind = MotionType(message.motion_type)
    except ValueError:
        raise _refuse(message, "unknown motion type") from None
    if kind is MotionType.SPLINE:
        raise _refuse(message, "send spline points as SplinePoint")
    return kind


def _flag(message: MotionPoint, kind: MotionType) -> int:
    """Index 14: arc mode for movec, has-q_near for pose targets, else 0 (checks the second block)."""
    second = message.via_or_qnear
    if kind in CIRCULAR_TYPES:
        if second is None:
            raise _refuse(message, f"{kind.name} needs a via point")
        if type(message.arc_mode) is not int or message.arc_mode not in ARC_MODES:
            raise _refuse(message, "arc_mode must be 0 (unconstrained) or 1 (fixed)")
        return message.arc_mode
    if message.arc_mode != 0:
        raise _refuse(message, f"arc_mode applies to movec only, not {kind.name}")
    if kind in POSE_TARGET_TYPES:
        return 0 if second is None else 1
    if second is not None:
        raise _refuse(message, f"{kind.name} has a joint target: no via point or q_near")
    return 0


def _check_speeds(message: MotionPoint, kind: MotionType) -> None:
    for what, value in (
        ("velocity", message.velocity),
        ("acceleration", message.acceleration),
        ("blend_radius", message.blend_radius),
    ):
        if not is_finite(value) or value < 0:
            raise _refuse(message, f"{what} must be finite and ≥ 0")  # urcl MotionPrimitive::validate
    if kind in OPTIMOVE_TYPES and not (0 < message.velocity <= 1 and 0 < message.acceleration <= 1):
        raise _refuse(message, "optimove velocity and acceleration are fractions in (0, 1]")


def _encode_motion(message: MotionPoint) -> bytes:
    kind = _motion_type(message)
    flag = _flag(message, kind)
    _check_speeds(message, kind)
    ints = _vector(message.target, "target")
    ints += _vector(message.via_or_qnear, "via_or_qnear")
    ints += (
        scale(message.velocity, PROTOCOL, "velocity"),
        scale(message.acceleration, PROTOCOL, "acceleration"),
        flag * MULT,  # the script divides index 14 by MULT_jointstate like every other field
        0,
        0,
        0,
        _duration(message, message.duration, "duration"),
        scale(message.blend_radius, PROTOCOL, "blend_radius"),  # scaled by MULT_TIME (§4.4 quirk)
        kind,
    )
    return FRAME.pack(*ints)


def _encode_result(message: TrajectoryResultMessage) -> bytes:
    try:
        return INT32.pack(TrajectoryResultCode(message.code))
    except ValueError:
        raise _refuse(message, "unknown result code") from None


_POINT_ENCODERS: Final[dict[type, Callable[[Any], bytes]]] = {
    SplinePoint: _encode_spline,
    MotionPoint: _encode_motion,
}
_RESULT_ENCODERS: Final[dict[type, Callable[[Any], bytes]]] = {TrajectoryResultMessage: _encode_result}


def encode_point(message: TrajectoryPoint) -> bytes:
    """The 84-byte frame of one point; LocalProtocolError if it is invalid or cannot be represented."""
    encode = _POINT_ENCODERS.get(type(message))
    if encode is None:
        raise LocalProtocolError(f"{PROTOCOL}: {message!r} is not a trajectory point", protocol=PROTOCOL)
    return encode(message)


# -- decoding ------------------------------------------------------------------------------------------

_MOTION_TYPES: Final = {t.value: t for t in MotionType}


def _unscaled(ints: tuple[int, ...], start: int) -> tuple[float, ...]:
    return tuple([i / MULT for i in ints[start : start + JOINTS]])


def _decode_spline(ints: tuple[int, ...]) -> SplinePoint | UnknownTrajectoryPoint:
    spline = ints[_I_BLEND]
    if spline == SplineType.CUBIC:
        accelerations = None  # the script does not read indices 12–17 of a cubic point
    elif spline == SplineType.QUINTIC:
        accelerations = _unscaled(ints, 2 * JOINTS)
    else:
        return UnknownTrajectoryPoint(MotionType.SPLINE, ints)  # the script answers FAILURE (§5.5)
    return SplinePoint(_unscaled(ints, 0), _unscaled(ints, JOINTS), accelerations, ints[_I_DURATION] / MULT)


def _decode_motion(ints: tuple[int, ...], kind: MotionType) -> MotionPoint:
    second: tuple[float, ...] | None = None
    arc_mode = 0
    if kind in CIRCULAR_TYPES:
        second = _unscaled(ints, JOINTS)
        whole = unscale_integral(ints[_I_FLAG])
        if whole is None:
            raise RemoteProtocolError(
                f"{PROTOCOL}: movec arc mode {ints[_I_FLAG] / MULT} is not a whole number", protocol=PROTOCOL
            )
        arc_mode = whole
    elif kind in POSE_TARGET_TYPES and ints[_I_FLAG] != 0:
        second = _unscaled(ints, JOINTS)  # the script tests the flag for truth: any non-zero value
    return MotionPoint(
        kind,
        _unscaled(ints, 0),
        second,
        ints[12] / MULT,
        ints[13] / MULT,
        ints[_I_BLEND] / MULT,
        ints[_I_DURATION] / MULT,
        arc_mode,
    )


def decode_point(data: bytes, offset: int = 0) -> SplinePoint | MotionPoint | UnknownTrajectoryPoint:
    """Decode the 84-byte point at ``data[offset:]``; RemoteProtocolError only for a fractional arc mode."""
    ints: tuple[int, ...] = FRAME.unpack_from(data, offset)
    kind = _MOTION_TYPES.get(ints[_I_TYPE])
    if kind is None:
        return UnknownTrajectoryPoint(ints[_I_TYPE], ints)  # the script skips it (no else branch; §5.5)
    if kind is MotionType.SPLINE:
        return _decode_spline(ints)
    return _decode_motion(ints, kind)


_RESULT_CODES: Final = {c.value: c for c in TrajectoryResultCode}


def _decode_result(data: bytes, offset: int) -> TrajectoryResult:
    (value,) = INT32.unpack_from(data, offset)
    code = _RESULT_CODES.get(value)
    if code is None:
        raise RemoteProtocolError(f"{PROTOCOL}: unknown trajectory result {value}", protocol=PROTOCOL)
    return TrajectoryResult(code)


# -- connection ----------------------------------------------------------------------------------------


class TrajectoryPointConnection(
    FixedFrameConnection[TrajectoryPoint | TrajectoryResultMessage, TrajectoryPointEvent]
):
    """One trajectory-point connection (§4.4), for either party.

    DAEMON: ``send(SplinePoint | MotionPoint)``; yields ``TrajectoryResult`` per 4 received bytes.
    ROBOT: yields ``SplinePoint | MotionPoint | UnknownTrajectoryPoint`` per 84 received bytes;
    ``send(TrajectoryResultMessage)``.
    """

    __slots__ = ()

    PROTOCOL = PROTOCOL

    def __init__(self, side: Side) -> None:
        if side is Side.DAEMON:
            super().__init__(side, receive_size=RESULT_BYTES, decode=_decode_result, encoders=_POINT_ENCODERS)
        else:
            super().__init__(side, receive_size=FRAME_BYTES, decode=decode_point, encoders=_RESULT_ENCODERS)
