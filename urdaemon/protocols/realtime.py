"""Real-time client interface (port 30003) as a sans-IO codec: the controller's state at its own rate.

Robot → client, once per controller cycle (500 Hz e-Series, 125 Hz CB3), one message of doubles::

    [ int32 message size, incl. these 4 bytes ][ double time ][ double q_target[6] ][ ... ]

every number big-endian, every field after the size a double (bit fields and modes too, as doubles).
The fields, in wire order (UR's "Client Interface" real-time table; the offsets agree with public
clients of it), are :data:`FIELDS`; a controller version sends a prefix of them (:func:`field_count`):

    =========================  ====  =====================================================
    up to ``program_state``    1060  CB3 3.0 - 3.4
    + elbow position/velocity  1108  CB3 3.5 and later
    + ``safety_status``        1116  e-Series 5.0 - 5.9
    + payload mass/cog/inert.  1196  e-Series 5.10 and later
    =========================  ====  =====================================================

Client → robot: URScript text, exactly as on the primary interface (a ``def``/``sec`` block or single
lines, newline-terminated; docs/protocols.md §2.4).

``RealtimeConnection(Side.ROBOT, version)`` sends :class:`RealtimeState` and receives the same
``ProgramReceived``/``CommandReceived`` events as the primary codec. ``RealtimeConnection(Side.DAEMON)``
sends :class:`~urdaemon.protocols.primary.Script` and receives one :class:`RealtimeState` per message,
decoding as many fields as the message's size holds (a newer controller's extra bytes are skipped, a
field an older one does not send keeps its default).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, fields
from typing import Final, TypeAlias

from urdaemon.protocols._buffer import Side
from urdaemon.protocols._codec import Codec
from urdaemon.protocols.primary import CommandReceived, PrimaryConnection, ProgramReceived, Script

__all__ = [
    "FIELDS",
    "MAX_MESSAGE_BYTES",
    "PROTOCOL",
    "REALTIME_PORT",
    "RealtimeConnection",
    "RealtimeEvent",
    "RealtimeState",
    "field_count",
    "message_size",
]

PROTOCOL: Final = "realtime"
REALTIME_PORT: Final = 30003
"""TCP port of the real-time client interface on the robot (§0)."""
MAX_MESSAGE_BYTES: Final = 4096
"""Largest message size accepted (bytes): today's layout is 1196; room for fields appended later."""

_SIZE: Final = struct.Struct(">i")
_DOUBLE_BYTES: Final = 8
_Vec: TypeAlias = tuple[float, ...]
_Z3: Final[_Vec] = (0.0,) * 3
_Z6: Final[_Vec] = (0.0,) * 6


@dataclass(frozen=True, slots=True)
class RealtimeState:
    """One real-time message. Vectors are 6 values per joint or ``x, y, z, rx, ry, rz`` unless noted."""

    time: float = 0.0
    q_target: _Vec = _Z6
    qd_target: _Vec = _Z6
    qdd_target: _Vec = _Z6
    i_target: _Vec = _Z6
    m_target: _Vec = _Z6
    q_actual: _Vec = _Z6
    qd_actual: _Vec = _Z6
    i_actual: _Vec = _Z6
    i_control: _Vec = _Z6
    tool_vector_actual: _Vec = _Z6
    tcp_speed_actual: _Vec = _Z6
    tcp_force: _Vec = _Z6
    tool_vector_target: _Vec = _Z6
    tcp_speed_target: _Vec = _Z6
    digital_input_bits: float = 0.0
    motor_temperatures: _Vec = _Z6
    controller_timer: float = 0.0
    test_value: float = 0.0
    robot_mode: float = 0.0
    joint_modes: _Vec = _Z6
    safety_mode: float = 0.0
    reserved_1: _Vec = _Z6
    tool_accelerometer_values: _Vec = _Z3
    reserved_2: _Vec = _Z6
    speed_scaling: float = 0.0
    linear_momentum_norm: float = 0.0
    reserved_3: float = 0.0
    reserved_4: float = 0.0
    v_main: float = 0.0
    v_robot: float = 0.0
    i_robot: float = 0.0
    v_actual: _Vec = _Z6
    digital_outputs: float = 0.0
    program_state: float = 0.0
    elbow_position: _Vec = _Z3
    elbow_velocity: _Vec = _Z3
    safety_status: float = 0.0
    payload_mass: float = 0.0
    payload_cog: _Vec = _Z3
    payload_inertia: _Vec = _Z6


FIELDS: Final[tuple[tuple[str, int], ...]] = tuple(
    (f.name, len(f.default) if isinstance(f.default, tuple) else 1) for f in fields(RealtimeState)
)
"""(name, number of doubles) of every field, in wire order (``reserved_*``: "used by UR software only")."""

_NAMES: Final = tuple(name for name, _ in FIELDS)
_VECTORS: Final = frozenset(f.name for f in fields(RealtimeState) if isinstance(f.default, tuple))
_OFFSETS: Final = tuple(4 + 8 * sum(n for _, n in FIELDS[:i]) for i in range(len(FIELDS) + 1))


def field_count(version: tuple[int, ...]) -> int:
    """How many of :data:`FIELDS` a controller of ``version`` (major, minor, ...) sends."""
    last = "program_state"
    if tuple(version[:2]) >= (5, 10):
        last = "payload_inertia"
    elif version[0] >= 5:
        last = "safety_status"
    elif tuple(version[:2]) >= (3, 5):
        last = "elbow_velocity"
    return _NAMES.index(last) + 1


def message_size(version: tuple[int, ...]) -> int:
    """The message size (bytes, incl. the size field) a controller of ``version`` sends."""
    return _OFFSETS[field_count(version)]


RealtimeEvent: TypeAlias = RealtimeState | ProgramReceived | CommandReceived


class RealtimeConnection(Codec["RealtimeState | Script", "RealtimeEvent"]):
    """One real-time-interface TCP connection, for either party; see the module docstring."""

    __slots__ = ("_daemon_script", "_encoded", "_packer", "_script", "version")

    PROTOCOL = PROTOCOL

    def __init__(self, side: Side, version: tuple[int, ...] = (5, 15)) -> None:
        super().__init__(side, MAX_MESSAGE_BYTES)
        self.version = tuple(version)
        count = field_count(self.version)
        self._encoded = _NAMES[:count]
        self._packer = struct.Struct(f">i{(_OFFSETS[count] - 4) // _DOUBLE_BYTES}d")
        self._script = PrimaryConnection(Side.ROBOT) if side is Side.ROBOT else None
        self._daemon_script = PrimaryConnection(Side.DAEMON) if side is Side.DAEMON else None

    def _parse(self, events: list[RealtimeEvent]) -> None:
        if self._script is not None:  # robot side: the primary codec's script text
            if len(self._buffer):
                # the robot-side primary codec yields only ProgramReceived and CommandReceived
                events += self._script.receive_data(self._buffer.take_all())  # type: ignore[arg-type]
            return
        buffer = self._buffer
        while (head := buffer.peek(_SIZE.size)) is not None:
            size = _SIZE.unpack(head)[0]
            if not _OFFSETS[1] <= size <= MAX_MESSAGE_BYTES:
                message = f"message size {size} outside [{_OFFSETS[1]}, {MAX_MESSAGE_BYTES}]"
                raise self._remote(message, self._consumed)
            message_bytes = buffer.take(size)
            if message_bytes is None:
                return
            events.append(_decode(message_bytes))
            self._consumed += size

    def _encode(self, message: RealtimeState | Script) -> None:
        if self._daemon_script is not None:
            if not isinstance(message, Script):
                raise self._local(f"the daemon sends only Script, not {message!r}")
            self._daemon_script.send(message)
            self._queue(self._daemon_script.data_to_send())
            return
        if not isinstance(message, RealtimeState):
            raise self._local(f"the robot sends only RealtimeState, not {message!r}")
        values: list[float] = []
        vectors = _VECTORS
        for name in self._encoded:
            value = getattr(message, name)
            if name in vectors:
                values += value
            else:
                values.append(value)
        try:
            self._queue(self._packer.pack(self._packer.size, *values))
        except struct.error as err:
            raise self._local(f"cannot encode {message!r}: {err}") from err


def _decode(message: bytes) -> RealtimeState:
    doubles = (len(message) - _SIZE.size) // _DOUBLE_BYTES
    values = struct.unpack_from(f">{doubles}d", message, _SIZE.size)
    kwargs: dict[str, float | _Vec] = {}
    pos = 0
    for name, count in FIELDS:
        if pos + count > doubles:
            break
        kwargs[name] = values[pos : pos + count] if name in _VECTORS else values[pos]
        pos += count
    return RealtimeState(**kwargs)  # type: ignore[arg-type]
