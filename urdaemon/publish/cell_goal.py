"""The cell goal's message (``<cell>/goal/trajectory``): each robot's trajectory goal and the abort
policy, as a client sends it (``CellGoalRequest``, ``cell_goal_body``) and split a piece at a time
(``CellGoalDecoder``); and the lease tokens a cell request carries as its attachment
(``lease_tokens_attachment``, ``decode_lease_tokens``, for the goal and its cancel)."""

from __future__ import annotations

import json
import re
from collections.abc import Generator
from dataclasses import dataclass
from typing import Any

from urdaemon.errors import MessageError
from urdaemon.publish import fields
from urdaemon.publish.envelope import (
    JSON_DECODER,
    MAX_MESSAGE_BYTES,
    SMALL_MESSAGE_BYTES,
    DuplicateField,
    check_version,
    client_text,
    duplicate_field,
)
from urdaemon.publish.trajectory_goal import TrajectoryGoalRequest, trajectory_goal_body

__all__ = [
    "CELL_GOAL_POLICIES",
    "CellGoalDecoder",
    "CellGoalMessage",
    "CellGoalRequest",
    "cell_goal_body",
    "decode_lease_tokens",
    "lease_tokens_attachment",
]

CELL_GOAL_POLICIES = ("stop_all", "continue")
"""What a cell goal does when one robot's part ends other than succeeded: stop the others, or not."""
_CELL_GOAL = "cell goal"
_CELL_KEY_BYTES = 256
"""Longest text of a field name or a robot name in a cell goal."""
_CELL_FIELD_BYTES = 1024
"""Longest text of a cell goal's own fields (``v``, ``on_abort``)."""
_SCAN_BYTES = 64 * 1024
"""Bytes searched for the next bracket or quote in one step, when a robot's part is delimited."""
_SCAN_TOKENS = 256
"""Brackets and texts passed in one step."""
_TEXT_BYTES = 16 * 1024
"""Longest JSON text (a quoted string) inside a robot's part."""
_STRUCTURE = re.compile(rb'[][{}"]')
_STRING_REST = re.compile(rb'(?:[^"\\]++|\\.)*+"')
_SPACE = re.compile(rb"[ \t\n\r]{0,4096}")


@dataclass(frozen=True, slots=True)
class CellGoalRequest:
    """A cell goal as a client sends it: each robot's trajectory goal, and the abort policy."""

    robots: dict[str, TrajectoryGoalRequest | dict[str, Any]]
    """Each robot's part: a ``TrajectoryGoalRequest``, or a whole trajectory goal body as the program
    gave it (sent as it is: the robot's decoder checks it)."""
    on_abort: str = CELL_GOAL_POLICIES[0]
    """One of ``CELL_GOAL_POLICIES``."""


def cell_goal_body(request: CellGoalRequest) -> dict[str, Any]:
    """The message's fields of ``request`` (``CellGoalDecoder``'s inverse, each part the trajectory
    decoder's)."""
    robots = {
        name: trajectory_goal_body(part) if isinstance(part, TrajectoryGoalRequest) else part
        for name, part in request.robots.items()
    }
    return {"robots": robots, "on_abort": request.on_abort}


@dataclass(frozen=True, slots=True)
class CellGoalMessage:
    """A cell goal as sent: each robot's trajectory goal body (undecoded), and the abort policy."""

    robots: dict[str, memoryview]
    on_abort: str


class CellGoalDecoder:
    """Splits a cell goal ``{"robots": {"alice": {...}, ...}, "on_abort": ...}`` into each robot's
    trajectory goal body, a piece at a time (``steps()``, a generator that returns it): a part
    is delimited by counting its brackets, never decoded here (each robot's own decoder does that,
    in slices too), so no step costs more than searching ``_SCAN_BYTES`` or passing
    ``_SCAN_TOKENS`` brackets. Every error is a ``MessageError``."""

    def __init__(self, payload: bytes | None, *, max_bytes: int = MAX_MESSAGE_BYTES) -> None:
        if payload is None or len(payload) == 0:
            raise MessageError(f"{_CELL_GOAL}: empty message; expected a JSON object")
        if len(payload) > max_bytes:
            raise MessageError(
                f"{_CELL_GOAL}: message of {len(payload)} bytes exceeds the limit of {max_bytes} bytes"
            )
        self._data = bytes(payload)
        self._decoder = JSON_DECODER

    def steps(self) -> Generator[None, None, CellGoalMessage]:
        """The split, one bounded step per ``next`` (runtime/slicing.py runs it in slices); returns the
        split goal."""
        return self._run()

    def _run(self) -> Generator[None, None, CellGoalMessage]:
        pos = self._expect(self._space(0), b"{", "a JSON object")
        own: dict[str, Any] = {}
        robots: dict[str, memoryview] | None = None
        if self._data.startswith(b"}", self._space(pos)):
            pos = self._space(pos) + 1
        else:
            while True:
                key, pos = self._value(pos, _CELL_KEY_BYTES, "a field name")
                if not isinstance(key, str):
                    raise MessageError(f"{_CELL_GOAL}: expected a field name at byte {pos}")
                pos = self._expect(pos, b":", "':' after a field name")
                if key in own or (key == "robots" and robots is not None):
                    raise duplicate_field(_CELL_GOAL, DuplicateField(key))
                if key == "robots":
                    robots, pos = yield from self._robots(pos)
                else:
                    own[key], pos = self._value(pos, _CELL_FIELD_BYTES, key)
                if self._data.startswith(b",", self._space(pos)):
                    pos = self._space(pos) + 1
                    continue
                pos = self._expect(pos, b"}", "',' or '}' after a field")
                break
        if self._space(pos) != len(self._data):
            raise MessageError(f"{_CELL_GOAL}: not valid JSON: extra data at byte {self._space(pos)}")
        return _cell_goal(own, robots)

    def _robots(self, pos: int) -> Generator[None, None, tuple[dict[str, memoryview], int]]:
        pos = self._expect(pos, b"{", f"{_CELL_GOAL}.robots: an object naming each robot's trajectory")
        robots: dict[str, memoryview] = {}
        if self._data.startswith(b"}", self._space(pos)):
            return robots, self._space(pos) + 1
        while True:
            name, pos = self._value(pos, _CELL_KEY_BYTES, "a robot name")
            if not isinstance(name, str):
                raise MessageError(f"{_CELL_GOAL}.robots: expected a robot name at byte {pos}")
            what = f"{_CELL_GOAL}.robots.{client_text(name)}"
            if name in robots:
                raise MessageError(f"{what}: the robot is named twice")
            pos = self._expect(pos, b":", "':' after a robot name")
            start = self._space(pos)
            if not self._data.startswith(b"{", start):
                raise MessageError(f"{what}: expected a trajectory goal (a JSON object)")
            end = yield from self._object_end(start, what)
            robots[name] = memoryview(self._data)[start:end]
            if self._data.startswith(b",", self._space(end)):
                pos = self._space(end) + 1
                continue
            return robots, self._expect(end, b"}", "',' or '}' after a robot's trajectory")

    def _object_end(self, pos: int, what: str) -> Generator[None, None, int]:
        """Where the object at ``pos`` ends: its brackets counted, quoted texts passed over."""
        data, depth, passed = self._data, 0, 0
        while True:
            found = _STRUCTURE.search(data, pos, pos + _SCAN_BYTES)
            if found is None:
                if pos + _SCAN_BYTES >= len(data):
                    raise MessageError(f"{what}: not valid JSON: the object does not end")
                pos += _SCAN_BYTES
                yield None
                continue
            char, pos = data[found.start()], found.end()
            if char == 0x22:  # a quoted text: passed over whole, brackets in it do not count
                text = _STRING_REST.match(data, pos, pos + _TEXT_BYTES)
                if text is None:
                    raise MessageError(
                        f"{what}: a text at byte {pos} is unterminated or over {_TEXT_BYTES} bytes"
                    )
                pos = text.end()
            elif char in b"{[":
                depth += 1
            else:
                depth -= 1
                if depth == 0:
                    return pos
            passed += 1
            if passed % _SCAN_TOKENS == 0:
                yield None

    def _value(self, pos: int, limit: int, what: str) -> tuple[Any, int]:
        """One JSON value of at most ``limit`` bytes at ``pos`` (after whitespace), and the byte after it."""
        pos = self._space(pos)
        window = self._data[pos : pos + limit]
        try:
            text = window.decode()
        except UnicodeDecodeError as err:
            if err.end < len(window) or pos + limit >= len(self._data):  # not a character cut short
                raise MessageError(f"{_CELL_GOAL}: not valid JSON: not UTF-8 text ({err.reason})") from err
            text = window[: err.start].decode()
        try:
            value, end = self._decoder.raw_decode(text)
        except DuplicateField as err:
            raise duplicate_field(f"{_CELL_GOAL}: {what}", err) from None
        except (ValueError, RecursionError) as err:
            raise MessageError(
                f"{_CELL_GOAL}: not valid JSON: {what} at byte {pos} is malformed or over {limit} bytes"
            ) from err
        return value, pos + len(text[:end].encode())

    def _space(self, pos: int) -> int:
        found = _SPACE.match(self._data, pos)
        return pos if found is None else found.end()

    def _expect(self, pos: int, char: bytes, what: str) -> int:
        pos = self._space(pos)
        if not self._data.startswith(char, pos):
            raise MessageError(f"{_CELL_GOAL}: not valid JSON: expected {what} at byte {pos}")
        return pos + 1


def _cell_goal(own: dict[str, Any], robots: dict[str, memoryview] | None) -> CellGoalMessage:
    check_version(own, _CELL_GOAL)
    fields.allowed(own, _CELL_GOAL, {"on_abort"})
    if not robots:
        raise MessageError(f"{_CELL_GOAL}.robots: expected an object naming at least one robot's trajectory")
    on_abort = own.get("on_abort", CELL_GOAL_POLICIES[0])
    if on_abort not in CELL_GOAL_POLICIES:
        raise MessageError(
            f"{_CELL_GOAL}.on_abort: expected one of {', '.join(CELL_GOAL_POLICIES)}, "
            f"got {fields.shown(on_abort)}"
        )
    return CellGoalMessage(robots, on_abort)


def lease_tokens_attachment(tokens: dict[str, str]) -> bytes:
    """A cell request's attachment: each robot's lease token (``decode_lease_tokens``' inverse)."""
    return json.dumps(tokens).encode()


def decode_lease_tokens(attachment: bytes | None, limit: int = SMALL_MESSAGE_BYTES) -> dict[str, bytes]:
    """A cell request's attachment: each robot's lease token, ``{"alice": T, ...}`` (empty: none)."""
    if attachment is None or len(attachment) == 0:
        return {}
    if len(attachment) > limit:
        raise MessageError(f"lease tokens: attachment of {len(attachment)} bytes exceeds {limit} bytes")
    try:
        data = JSON_DECODER.decode(attachment.decode())
    except DuplicateField as err:
        raise duplicate_field("lease tokens", err) from None
    except (ValueError, RecursionError) as err:
        raise MessageError("lease tokens: the attachment is not a JSON object of robot tokens") from err
    if not isinstance(data, dict) or not all(isinstance(v, str) for v in data.values()):
        raise MessageError('lease tokens: the attachment must be a JSON object {"<robot>": "<token>", ...}')
    # a token that is not ASCII is no holder's token: kept (as one that matches none), so the robot
    # it names is still checked and refused naming its lease
    return {name: token.encode() if token.isascii() else b"" for name, token in data.items()}
