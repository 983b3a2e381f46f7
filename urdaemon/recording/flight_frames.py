"""The flight recorder's pipe: what the daemon writes on its process's stdin, as length-prefixed
binary frames (runtime/flight_recorder.py writes them, recording/flight.py reads them).

A frame is a 15-byte header, little endian: ``kind`` (u8), the key's length (u16), the payload's
length (u32), a time (i64, Unix ns), then the key (UTF-8) and the payload. Kinds:

- ``SAMPLE`` (0): a message the daemon published: its key, its payload, and the time of the batch it
  was sent in (one clock read per batch of about 50 ms, not one per message);
- ``REQUEST`` (1): a request as JSON, no key: ``{"reason": "internal_error"}``, ``{"reason":
  "request", "id": "3"}``;
- ``URDF`` (2): the cell URDF, no key, sent first each time the process starts.

Only the daemon writes the pipe, so a frame that cannot be read (an unknown kind, a length over the
bounds) is a bug: ``FrameError``, and the process stops (the daemon starts it again).

No IO, no clock: bytes in, frames out.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable

__all__ = [
    "HEADER",
    "MAX_PAYLOAD",
    "REQUEST",
    "SAMPLE",
    "URDF",
    "Frame",
    "FrameError",
    "FrameReader",
    "encode_frame",
    "encode_samples",
]

SAMPLE, REQUEST, URDF = 0, 1, 2
_KINDS = (SAMPLE, REQUEST, URDF)
HEADER = struct.Struct("<BHIq")
MAX_PAYLOAD = 64 * 1024 * 1024
"""The largest payload a frame may carry (the largest message, a URDF, is a few MB)."""

Frame = tuple[int, str, bytes, int]
"""kind, key, payload, time (Unix ns)."""


class FrameError(ValueError):
    """Bytes on the pipe that are no frame."""


def encode_frame(kind: int, key: str, payload: bytes, time_ns: int) -> bytes:
    """One frame."""
    k = key.encode()
    return HEADER.pack(kind, len(k), len(payload), time_ns) + k + payload


def encode_samples(items: Iterable[tuple[str, bytes]], time_ns: int) -> bytes:
    """``SAMPLE`` frames of ``items`` (key, payload), all stamped ``time_ns``, joined for one write."""
    pack = HEADER.pack
    parts: list[bytes] = []
    add = parts.append
    for key, payload in items:
        k = key.encode()
        add(pack(SAMPLE, len(k), len(payload), time_ns))
        add(k)
        add(payload)
    return b"".join(parts)


class FrameReader:
    """Frames out of the bytes read from the pipe, however the reads split them."""

    __slots__ = ("_buffer",)

    def __init__(self) -> None:
        self._buffer = bytearray()

    @property
    def pending(self) -> int:
        """Bytes read that are not a whole frame yet (at the pipe's end: a frame cut short)."""
        return len(self._buffer)

    def feed(self, data: bytes) -> list[Frame]:
        """The whole frames ``data`` completes, in order; ``FrameError`` at bytes that are no frame
        (the reader is then of no further use)."""
        buffer = self._buffer
        buffer += data
        frames: list[Frame] = []
        unpack = HEADER.unpack_from
        size = HEADER.size
        end = len(buffer)
        at = 0
        while end - at >= size:
            kind, key_len, payload_len, time_ns = unpack(buffer, at)
            if kind not in _KINDS:
                raise FrameError(f"unknown frame kind {kind} at byte {at} of a read")
            if payload_len > MAX_PAYLOAD:
                raise FrameError(f"a frame's payload of {payload_len} bytes exceeds {MAX_PAYLOAD}")
            start = at + size
            stop = start + key_len + payload_len
            if stop > end:
                break
            try:
                key = buffer[start : start + key_len].decode()
            except UnicodeDecodeError as err:
                raise FrameError(f"a frame's key is not UTF-8: {err}") from None
            frames.append((kind, key, bytes(buffer[start + key_len : stop]), time_ns))
            at = stop
        del buffer[:at]
        return frames
