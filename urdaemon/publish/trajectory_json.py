"""A trajectory goal decoded a piece at a time, so even the largest one never holds the event loop.

``json.loads`` of a 2 MiB goal holds the loop (and with it every robot's cycle) for tens of
milliseconds, and a worker thread would not help: the decoder holds the GIL. Here the message is
taken apart by hand at its top level and in its ``points`` array, and every value is handed to
``json.JSONDecoder.raw_decode`` on a bounded window of the text, so no single step costs more than
decoding that window: one point (at most ``POINT_CHARS``), or one other field (at most
``FIELD_CHARS``). ``steps()`` is the work as a generator (one bounded step per ``next``, the goal
its return value), the one shape of stepped work the runtime runs in slices (runtime/slicing.py). The
values read are checked and the goal built by trajectory_goal.py; ``decode_trajectory_goal`` decodes
one at once.
"""

from __future__ import annotations

import codecs
import re
from collections.abc import Generator
from typing import Any

from urdaemon.control.goal_types import TrajectoryPoint
from urdaemon.errors import MessageError
from urdaemon.publish.envelope import (
    JSON_DECODER,
    MAX_MESSAGE_BYTES,
    DuplicateField,
    client_text,
    duplicate_field,
)
from urdaemon.publish.trajectory_goal import (
    MAX_TRAJECTORY_POINTS,
    TrajectoryGoalMessage,
    trajectory_goal,
    trajectory_point,
)

__all__ = ["FIELD_CHARS", "POINT_CHARS", "TrajectoryGoalDecoder", "decode_trajectory_goal"]

POINT_CHARS = 16 * 1024
"""Longest text of one point (three lists of 64 long numbers fit; a 6-joint point is ~0.4 KiB)."""
FIELD_CHARS = 16 * 1024
"""Longest text of a top-level field other than ``points`` (joint names, tolerances)."""
KEY_CHARS = 256
"""Longest text of a field name."""
TEXT_CHUNK = 128 * 1024
"""Bytes turned into text per step."""
WHITESPACE_CHARS = 4096
"""Longest run of whitespace between two tokens."""
_WHAT = "trajectory goal"
_WHITESPACE = re.compile(r"[ \t\n\r]*")


def decode_trajectory_goal(payload: bytes | None) -> TrajectoryGoalMessage:
    """Decode a trajectory goal at once (the daemon uses ``TrajectoryGoalDecoder``, in slices)."""
    steps = TrajectoryGoalDecoder(payload).steps()
    while True:
        try:
            next(steps)
        except StopIteration as stop:
            return stop.value  # type: ignore[no-any-return]


class TrajectoryGoalDecoder:
    """Decodes one trajectory goal in steps (``steps()``).

    The size is checked before anything is read. Every error is a ``MessageError`` naming the field.
    """

    def __init__(self, payload: bytes | bytearray | memoryview | None, *, max_bytes: int = MAX_MESSAGE_BYTES):
        if payload is None or len(payload) == 0:
            raise MessageError(f"{_WHAT}: empty message; expected a JSON object")
        if len(payload) > max_bytes:
            raise MessageError(
                f"{_WHAT}: message of {len(payload)} bytes exceeds the limit of {max_bytes} bytes"
            )
        self._payload = payload
        self._decoder = JSON_DECODER

    def steps(self) -> Generator[None, None, TrajectoryGoalMessage]:
        """The decoding, one bounded step per ``next``; returns the goal. Raises ``MessageError``."""
        return self._run()

    # ---- the steps ---------------------------------------------------------------------------------

    def _run(self) -> Generator[None, None, TrajectoryGoalMessage]:
        text = yield from self._text()
        pos = _skip(text, 0)
        if not text.startswith("{", pos):
            value, _ = self._decode(text, pos, FIELD_CHARS, "the message")
            raise MessageError(f"{_WHAT}: expected a JSON object, got {type(value).__name__}")
        pos += 1
        data: dict[str, Any] = {}
        points: tuple[TrajectoryPoint, ...] | None = None
        pos = _skip(text, pos)
        if text.startswith("}", pos):
            pos += 1
        else:
            while True:
                key, pos = self._decode(text, pos, KEY_CHARS, "a field name")
                if not isinstance(key, str):
                    raise MessageError(f"{_WHAT}: expected a field name at character {pos}")
                pos = self._expect(text, _skip(text, pos), ":", "':' after a field name")
                pos = _skip(text, pos)
                if key in data or (key == "points" and points is not None):
                    raise duplicate_field(_WHAT, DuplicateField(key))
                if key == "points":
                    points, pos = yield from self._points(text, pos)
                else:
                    data[key], pos = self._decode(text, pos, FIELD_CHARS, key)
                    yield
                pos = _skip(text, pos)
                if text.startswith(",", pos):
                    pos = _skip(text, pos + 1)
                    continue
                pos = self._expect(text, pos, "}", "',' or '}' after a field")
                break
        if _skip(text, pos) != len(text):
            raise MessageError(f"{_WHAT}: not valid JSON: extra data at character {_skip(text, pos)}")
        if points is None:
            raise MessageError(f"{_WHAT}.points: expected a list of points")
        return trajectory_goal(data, points)

    def _text(self) -> Generator[None, None, str]:
        """The payload as text, decoded ``TEXT_CHUNK`` bytes a step."""
        payload = bytes(self._payload)
        decoder = codecs.getincrementaldecoder("utf-8")()
        parts = []
        try:
            for start in range(0, len(payload), TEXT_CHUNK):
                parts.append(decoder.decode(payload[start : start + TEXT_CHUNK]))
                yield None
            parts.append(decoder.decode(b"", final=True))
        except UnicodeDecodeError as err:
            raise MessageError(f"{_WHAT}: not valid JSON: not UTF-8 text ({err.reason})") from err
        return "".join(parts)

    def _points(self, text: str, pos: int) -> Generator[None, None, tuple[tuple[TrajectoryPoint, ...], int]]:
        if not text.startswith("[", pos):
            self._decode(text, pos, FIELD_CHARS, "points")  # not JSON is said as such
            raise MessageError(f"{_WHAT}.points: expected a list of points")
        pos = _skip(text, pos + 1)
        points: list[TrajectoryPoint] = []
        if text.startswith("]", pos):
            return tuple(points), pos + 1
        while True:
            if len(points) == MAX_TRAJECTORY_POINTS:
                raise MessageError(f"{_WHAT}.points: more than {MAX_TRAJECTORY_POINTS} points")
            field = f"{_WHAT}.points[{len(points)}]"
            raw, pos = self._decode(text, pos, POINT_CHARS, f"points[{len(points)}]")
            points.append(trajectory_point(raw, field))
            yield None
            pos = _skip(text, pos)
            if text.startswith(",", pos):
                pos = _skip(text, pos + 1)
                continue
            pos = self._expect(text, pos, "]", "',' or ']' after a point")
            return tuple(points), pos

    def _decode(self, text: str, pos: int, limit: int, what: str) -> tuple[Any, int]:
        """One JSON value at ``pos`` of at most ``limit`` characters, and the position after it."""
        window = text[pos : pos + limit]
        try:
            value, end = self._decoder.raw_decode(window)
        except DuplicateField as err:
            raise duplicate_field(f"{_WHAT}: {what}", err) from None
        except RecursionError as err:
            raise MessageError(f"{_WHAT}: not valid JSON: {what} is nested too deeply") from err
        except ValueError as err:  # JSONDecodeError; an integer of too many digits
            if pos + limit < len(text):
                raise MessageError(
                    f"{_WHAT}: not valid JSON: {what} at character {pos} is malformed or longer than "
                    f"{limit} characters"
                ) from err
            raise MessageError(f"{_WHAT}: not valid JSON: {what}: {client_text(str(err), 120)}") from err
        return value, pos + end

    @staticmethod
    def _expect(text: str, pos: int, char: str, what: str) -> int:
        if not text.startswith(char, pos):
            raise MessageError(f"{_WHAT}: not valid JSON: expected {what} at character {pos}")
        return pos + 1


def _skip(text: str, pos: int) -> int:
    """The position of the first non-whitespace character at or after ``pos``."""
    match = _WHITESPACE.match(text, pos, pos + WHITESPACE_CHARS)
    end = match.end() if match is not None else pos
    if end == pos + WHITESPACE_CHARS and end < len(text):
        raise MessageError(f"{_WHAT}: more than {WHITESPACE_CHARS} whitespace characters at character {pos}")
    return end
