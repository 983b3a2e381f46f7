"""The ROS 2 messages the recorder stores, in CDR (little endian, XCDR1), written and read by hand.

Four message types, fixed at build time, so a few ``struct`` calls each instead of a general
serializer: ``sensor_msgs/msg/JointState``, ``geometry_msgs/msg/PoseStamped``,
``tf2_msgs/msg/TFMessage`` and ``std_msgs/msg/String``. The rules (docs/recording.md, "CDR"):
a 4-byte encapsulation header (``00 01 00 00``: CDR, little endian), then each field aligned to its
own size counted from the end of that header; a string is a uint32 length that counts a closing NUL,
the UTF-8 bytes and the NUL; a sequence is a uint32 count, then its elements. The tests check every
encoder against rosbags' serializer, an implementation written by others.

Pure: bytes out, bytes in; a malformed buffer raises ``ValueError`` naming what was wrong.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass

__all__ = [
    "JointStateMessage",
    "PoseStampedMessage",
    "TransformMessage",
    "decode_joint_state",
    "decode_pose_stamped",
    "decode_string",
    "decode_tf",
    "encode_joint_state",
    "encode_pose_stamped",
    "encode_string",
    "encode_tf",
    "encode_transforms",
    "stamp_of",
]

HEADER = b"\x00\x01\x00\x00"
"""The encapsulation header: plain CDR, little endian."""

_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")
_POSE = struct.Struct("<7d")


def stamp_of(time_ns: int) -> tuple[int, int]:
    """A ``builtin_interfaces/Time`` (sec, nanosec) of Unix nanoseconds; its int32 seconds end in 2038."""
    sec, nanosec = divmod(time_ns, 1_000_000_000)
    if not -(2**31) <= sec < 2**31:
        raise ValueError(f"time {time_ns} ns is outside builtin_interfaces/Time's int32 seconds")
    return sec, nanosec


@dataclass(frozen=True, slots=True)
class JointStateMessage:
    """A decoded ``sensor_msgs/msg/JointState``."""

    time_ns: int
    frame_id: str
    names: tuple[str, ...]
    position: tuple[float, ...]
    velocity: tuple[float, ...]
    effort: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class PoseStampedMessage:
    """A decoded ``geometry_msgs/msg/PoseStamped``: position then quaternion (x, y, z, w)."""

    time_ns: int
    frame_id: str
    pose: tuple[float, float, float, float, float, float, float]


@dataclass(frozen=True, slots=True)
class TransformMessage:
    """One ``geometry_msgs/msg/TransformStamped`` of a ``tf2_msgs/msg/TFMessage``."""

    time_ns: int
    frame_id: str
    child_frame_id: str
    transform: tuple[float, float, float, float, float, float, float]


class _Writer:
    """An output buffer that aligns each field to its size, counted after the encapsulation header."""

    __slots__ = ("buf",)

    def __init__(self) -> None:
        self.buf = bytearray(HEADER)

    def align(self, size: int) -> None:
        pad = -(len(self.buf) - 4) % size
        if pad:
            self.buf += bytes(pad)

    def u32(self, value: int) -> None:
        self.align(4)
        self.buf += _U32.pack(value)

    def string(self, text: str) -> None:
        data = text.encode()
        self.u32(len(data) + 1)
        self.buf += data
        self.buf += b"\x00"

    def header(self, time_ns: int, frame_id: str) -> None:
        self.align(4)
        self.buf += _STAMP.pack(*stamp_of(time_ns))
        self.string(frame_id)

    def doubles(self, values: Sequence[float]) -> None:
        self.u32(len(values))
        if values:
            self.align(8)
            self.buf += struct.pack(f"<{len(values)}d", *values)

    def fixed_doubles(self, values: Sequence[float]) -> None:
        self.align(8)
        self.buf += _POSE.pack(*values)


class _Reader:
    """Reads what ``_Writer`` writes; every read past the end raises ``ValueError`` naming the field."""

    __slots__ = ("data", "pos")

    def __init__(self, data: bytes | memoryview, what: str) -> None:
        self.data = bytes(data)
        if self.data[:2] != HEADER[:2]:
            raise ValueError(f"{what}: not little-endian CDR (header {self.data[:4].hex()!r})")
        self.pos = 4

    def align(self, size: int) -> None:
        self.pos += -(self.pos - 4) % size

    def take(self, size: int, field: str) -> bytes:
        end = self.pos + size
        if size < 0 or end > len(self.data):
            raise ValueError(f"{field}: the message ends at byte {len(self.data)}, before byte {end}")
        chunk = self.data[self.pos : end]
        self.pos = end
        return chunk

    def u32(self, field: str) -> int:
        self.align(4)
        value: int = _U32.unpack(self.take(4, field))[0]
        return value

    def string(self, field: str) -> str:
        size = self.u32(field)
        raw = self.take(size, field)
        if not raw or raw[-1] != 0:
            raise ValueError(f"{field}: a string without its closing NUL")
        return raw[:-1].decode()

    def header(self, field: str) -> tuple[int, str]:
        self.align(4)
        sec, nanosec = _STAMP.unpack(self.take(8, f"{field}.stamp"))
        return sec * 1_000_000_000 + nanosec, self.string(f"{field}.frame_id")

    def doubles(self, field: str) -> tuple[float, ...]:
        count = self.u32(field)
        if count == 0:
            return ()
        self.align(8)
        return struct.unpack(f"<{count}d", self.take(8 * count, field))

    def fixed_doubles(self, field: str) -> tuple[float, float, float, float, float, float, float]:
        self.align(8)
        values: tuple[float, float, float, float, float, float, float] = _POSE.unpack(self.take(56, field))
        return values


def encode_joint_state(
    time_ns: int,
    names: Sequence[str],
    position: Sequence[float],
    velocity: Sequence[float],
    effort: Sequence[float],
    frame_id: str = "",
) -> bytes:
    """``sensor_msgs/msg/JointState``."""
    out = _Writer()
    out.header(time_ns, frame_id)
    out.u32(len(names))
    for name in names:
        out.string(name)
    out.doubles(position)
    out.doubles(velocity)
    out.doubles(effort)
    return bytes(out.buf)


def decode_joint_state(data: bytes | memoryview) -> JointStateMessage:
    """Read a ``sensor_msgs/msg/JointState``."""
    inp = _Reader(data, "JointState")
    time_ns, frame_id = inp.header("header")
    count = inp.u32("name")
    if count > len(inp.data):
        raise ValueError(f"name: {count} names cannot fit in {len(inp.data)} bytes")
    names = tuple(inp.string(f"name[{i}]") for i in range(count))
    position = inp.doubles("position")
    velocity = inp.doubles("velocity")
    effort = inp.doubles("effort")
    return JointStateMessage(time_ns, frame_id, names, position, velocity, effort)


def encode_pose_stamped(time_ns: int, frame_id: str, pose: Sequence[float]) -> bytes:
    """``geometry_msgs/msg/PoseStamped``; ``pose`` is x, y, z, qx, qy, qz, qw."""
    out = _Writer()
    out.header(time_ns, frame_id)
    out.fixed_doubles(pose)
    return bytes(out.buf)


def decode_pose_stamped(data: bytes | memoryview) -> PoseStampedMessage:
    """Read a ``geometry_msgs/msg/PoseStamped``."""
    inp = _Reader(data, "PoseStamped")
    time_ns, frame_id = inp.header("header")
    return PoseStampedMessage(time_ns, frame_id, inp.fixed_doubles("pose"))


def encode_tf(time_ns: int, frame_id: str, links: Sequence[tuple[str, Sequence[float]]]) -> bytes:
    """``tf2_msgs/msg/TFMessage``: one transform from ``frame_id`` to each link (name, x, y, z, qx, qy,
    qz, qw), all stamped ``time_ns``."""
    return encode_transforms(time_ns, [(frame_id, child, pose) for child, pose in links])


def encode_transforms(time_ns: int, transforms: Sequence[tuple[str, str, Sequence[float]]]) -> bytes:
    """``tf2_msgs/msg/TFMessage`` of (parent, child, x, y, z, qx, qy, qz, qw) transforms, all stamped
    ``time_ns``."""
    out = _Writer()
    out.u32(len(transforms))
    for parent, child, transform in transforms:
        out.header(time_ns, parent)
        out.string(child)
        out.fixed_doubles(transform)
    return bytes(out.buf)


def decode_tf(data: bytes | memoryview) -> tuple[TransformMessage, ...]:
    """Read a ``tf2_msgs/msg/TFMessage``."""
    inp = _Reader(data, "TFMessage")
    count = inp.u32("transforms")
    if count > len(inp.data):
        raise ValueError(f"transforms: {count} transforms cannot fit in {len(inp.data)} bytes")
    found = []
    for i in range(count):
        time_ns, frame_id = inp.header(f"transforms[{i}].header")
        child = inp.string(f"transforms[{i}].child_frame_id")
        found.append(TransformMessage(time_ns, frame_id, child, inp.fixed_doubles(f"transforms[{i}]")))
    return tuple(found)


def encode_string(text: str) -> bytes:
    """``std_msgs/msg/String``."""
    out = _Writer()
    out.string(text)
    return bytes(out.buf)


def decode_string(data: bytes | memoryview) -> str:
    """Read a ``std_msgs/msg/String``."""
    return _Reader(data, "String").string("data")
