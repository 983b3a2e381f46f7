"""Shared pieces of the fixed-frame callback protocols (§0, §4.1): scaled ints and a base connection.

The reverse (50001), trajectory point (50003) and script command (50004) interfaces carry fixed-size
arrays of big-endian int32 with no length prefix. Most fields are "scaled ints",
``round(value × MULT)`` with ``MULT = 1 000 000`` (the script's ``MULT_jointstate`` and ``MULT_time``),
giving a range of ±2147.483647 at a resolution of 1e-6.

Scaling never wraps: a value that is NaN, infinite or outside int32 after scaling raises
``LocalProtocolError``. Decoding divides by ``MULT`` (true division, ``raw / MULT``) so that a value
that was already a multiple of 1e-6 comes back as exactly the same float.
"""

from __future__ import annotations

import math
import numbers
import struct
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, Final, NoReturn, TypeVar

from urdaemon.errors import LocalProtocolError, RemoteProtocolError
from urdaemon.protocols._buffer import Side
from urdaemon.protocols._codec import Codec, CodecState

__all__ = [
    "INT32",
    "INT32_MAX",
    "INT32_MIN",
    "MS_PER_S",
    "MULT",
    "MULT_JOINTSTATE",
    "MULT_TIME",
    "FixedFrameConnection",
    "from_ms",
    "int32_frame",
    "is_finite",
    "scale",
    "scale_vector",
    "to_ms",
    "unscale_integral",
]

MULT: Final = 1_000_000
"""Scale factor of every scaled int, dimensionless (urcl ``MULT_JOINTSTATE`` = ``MULT_TIME``; §0)."""
MULT_JOINTSTATE: Final = MULT
"""Scale of positions, velocities, poses, forces … (§5.1 ``{{JOINT_STATE_REPLACE}}``)."""
MULT_TIME: Final = MULT
"""Scale of durations and, by a urcl quirk, blend radii (§5.1 ``{{TIME_REPLACE}}``, §4.4 index 19)."""

INT32_MIN: Final = -(2**31)
INT32_MAX: Final = 2**31 - 1
MS_PER_S: Final = 1000
"""Timeouts are seconds on our API and whole milliseconds on the wire (§4.2 index 0)."""

INT32: Final = struct.Struct(">i")
"""One big-endian int32: the 4-byte results sent back on 50003 and 50004 (§4.4, §4.5)."""


def int32_frame(count: int) -> struct.Struct:
    """A precompiled struct of ``count`` big-endian int32 (build once at import time, never per message)."""
    return struct.Struct(f">{count}i")


def _refuse(protocol: str, what: str, value: object) -> NoReturn:
    raise LocalProtocolError(
        f"{protocol}: {what} = {value!r} does not fit a scaled int32 (finite, |value| ≤ 2147.483647)",
        protocol=protocol,
    )


def _is_real(value: object) -> bool:
    # float, int, bool and numpy scalars; not str, list or None (the API is typed float, callers are not)
    return isinstance(value, numbers.Real)


def scale(value: float, protocol: str, what: str) -> int:
    """``round(value × MULT)`` as an int32; LocalProtocolError for NaN, inf, out of range or not a number."""
    if not _is_real(value):  # before multiplying: "x" * MULT would build a 1 MB string
        _refuse(protocol, what, value)
    try:
        raw = round(value * MULT)
    except (ValueError, OverflowError):  # NaN, inf
        _refuse(protocol, what, value)
    if not INT32_MIN <= raw <= INT32_MAX:
        _refuse(protocol, what, value)
    return raw


def scale_vector(values: Sequence[float], length: int, protocol: str, what: str) -> list[int]:
    """Scale exactly ``length`` values; LocalProtocolError for a wrong length or any unscalable value."""
    try:
        count = len(values)
    except TypeError:
        count = -1
    if count != length:
        raise LocalProtocolError(
            f"{protocol}: {what} needs {length} values, got {values!r}", protocol=protocol
        )
    return [scale(v, protocol, what) for v in values]


def unscale_integral(raw: int) -> int | None:
    """The whole number a scaled int stands for, or None if it is not a whole number."""
    whole, rest = divmod(raw, MULT)
    return whole if rest == 0 else None


def to_ms(seconds: float, protocol: str, what: str = "timeout") -> int:
    """Seconds → whole milliseconds (rounded) as an int32; LocalProtocolError for NaN, inf or out of range."""
    ms: int | None = None
    if _is_real(seconds):
        try:
            ms = round(seconds * MS_PER_S)
        except (ValueError, OverflowError):  # NaN, inf
            ms = None
    if ms is None or not INT32_MIN <= ms <= INT32_MAX:
        raise LocalProtocolError(
            f"{protocol}: {what} = {seconds!r} s is not an int32 of ms", protocol=protocol
        )
    return ms


def from_ms(ms: int) -> float:
    """Whole milliseconds → seconds."""
    return ms / MS_PER_S


def is_finite(value: float) -> bool:
    """True for a real, finite number (helper for validators)."""
    try:
        return math.isfinite(value)
    except (TypeError, OverflowError):  # not a number, or an int too large for a float
        return False


MessageT = TypeVar("MessageT")
EventT = TypeVar("EventT")


class FixedFrameConnection(Codec[MessageT, EventT]):
    """Base of the fixed-frame codecs: owns framing, the error state and the send queue.

    A subclass sets ``PROTOCOL`` and passes, for its side, the size of the frames it receives, a
    ``decode(data, offset)`` that turns the complete frame starting at ``data[offset]`` into one event
    (or raises ``RemoteProtocolError``), and the encoders of the message types this side may send
    (each returns the bytes of one message or raises ``LocalProtocolError``). A receive size of 0 means
    "this side expects nothing": received bytes are counted and dropped, and more than ``ignore_limit``
    of them is a ``RemoteProtocolError``.
    """

    __slots__ = ("_decode", "_encoders", "_ignore_limit", "_ignored", "_size")

    PROTOCOL: ClassVar[str] = "fixed"

    def __init__(
        self,
        side: Side,
        *,
        receive_size: int,
        decode: Callable[[bytes, int], EventT],
        encoders: Mapping[type, Callable[[Any], bytes]],
        ignore_limit: int = 0,
    ) -> None:
        # Only a partial frame ever waits in the buffer, so one frame is the cap (checked before buffering).
        super().__init__(side, max(receive_size, 1))
        self._decode = decode
        self._encoders = encoders
        self._size = receive_size
        self._ignore_limit = ignore_limit
        self._ignored = 0

    # -- public API -----------------------------------------------------------------------------------

    @property
    def ignored_bytes(self) -> int:
        """Bytes received on a side that expects none (counted, then dropped)."""
        return self._ignored

    def receive_data(self, data: bytes | bytearray | memoryview) -> list[EventT]:
        """Feed received bytes; one event per complete frame. RemoteProtocolError on bad input."""
        if self._stream is not CodecState.OPEN:
            self._raise_not_open()
        try:
            if self._size == 0:
                self._ignore(len(data))
                return []
            return self._frames(bytes(data))
        except RemoteProtocolError:
            self._fail()
            raise

    def receive_eof(self) -> list[EventT]:
        """The peer closed; RemoteProtocolError if it closed in the middle of a frame."""
        if self._stream is not CodecState.OPEN:
            self._raise_not_open()
        if len(self._buffer):
            self._fail()
            raise RemoteProtocolError(
                f"{self.PROTOCOL}: connection closed after {len(self._buffer)} of {self._size} frame bytes",
                protocol=self.PROTOCOL,
                offset=self._consumed,
            )
        self._stream = CodecState.EOF
        return []

    def send(self, message: MessageT) -> None:
        """Queue one message; LocalProtocolError if it is illegal or not ours to send.

        The base's send with ``_encode`` inlined: a reverse frame goes out 500 times a second.
        """
        if self._stream is CodecState.ERROR:
            raise self._local("connection already failed")
        encode = self._encoders.get(type(message))
        if encode is None:
            raise self._local(f"the {self.side.value} side does not send {type(message).__name__}")
        self._out += encode(message)

    # -- internals ------------------------------------------------------------------------------------

    def _frames(self, data: bytes) -> list[EventT]:
        size = self._size
        events: list[EventT] = []
        pos = 0
        if len(self._buffer):
            pos = min(size - len(self._buffer), len(data))
            self._buffer.feed(data[:pos])
            frame = self._buffer.take(size)
            if frame is None:
                return events
            events.append(self._decode_at(frame, 0, self._consumed))
            self._consumed += size
        end = pos + (len(data) - pos) // size * size
        while pos < end:
            events.append(self._decode_at(data, pos, self._consumed))
            self._consumed += size
            pos += size
        self._buffer.feed(data[end:])
        return events

    def _decode_at(self, data: bytes, pos: int, stream_offset: int) -> EventT:
        try:
            return self._decode(data, pos)
        except RemoteProtocolError as err:
            if err.offset is None:
                err.offset = stream_offset
            raise

    def _ignore(self, count: int) -> None:
        self._ignored += count
        if self._ignored > self._ignore_limit:
            raise RemoteProtocolError(
                f"{self.PROTOCOL}: the {self.side.value} side expects no data, "
                f"but more than {self._ignore_limit} bytes arrived",
                protocol=self.PROTOCOL,
            )

    def _raise_not_open(self) -> NoReturn:
        if self._stream is CodecState.ERROR:
            raise RemoteProtocolError(
                f"{self.PROTOCOL}: connection is in an error state", protocol=self.PROTOCOL
            )
        raise LocalProtocolError(f"{self.PROTOCOL}: data fed after receive_eof()", protocol=self.PROTOCOL)
