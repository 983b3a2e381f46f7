"""The one message encoding: UTF-8 JSON objects carrying ``"v": 1`` (docs/keys.md).

The envelope every message shares, in and out: the schema version, the size limits, a client's
message parsed into a JSON object (``decode_message``), a message encoded (``encode``), a decoded
message type as the fields a client sends (``message_body``, the decoders' inverse), a client's
text made safe to echo (``client_text``); and the replies built on it: a message's time fields
(``state_time``) and a goal's feedback and result. The decoders of each request are modules of their
own (fields.py holds the checks they share); the hot-path state messages are state_encoder.py's.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping
from typing import Any

from urdaemon.control.goal_types import GoalFeedback, GoalResult
from urdaemon.errors import MessageError
from urdaemon.model import RobotState

__all__ = [
    "CLIENT_TEXT_CHARS",
    "JSON_DECODER",
    "MAX_MESSAGE_BYTES",
    "SCHEMA_VERSION",
    "SMALL_MESSAGE_BYTES",
    "DuplicateField",
    "check_version",
    "client_text",
    "decode_message",
    "duplicate_field",
    "encode",
    "encode_feedback",
    "encode_result",
    "message_body",
    "state_time",
]

SCHEMA_VERSION = 1
SMALL_MESSAGE_BYTES = 16 * 1024
"""Largest message on every key but the trajectory goal's (moves, stream commands, services). The
largest valid one, a move of 64 joints with every field (64 names of 64 characters, 64 positions
and 64 path and goal tolerances of 24-character numbers), is 8.7 KB as compact JSON, 10.0 KB
indented; a joint position command with positions and velocities 7.7 KB. 16 KiB leaves ~1.6x room
and bounds the loop time a message within the limit can cost (garbage this size: ~0.25 ms)."""
MAX_MESSAGE_BYTES = 2 * 1024 * 1024
"""Largest trajectory goal (5 000 points with positions, velocities and accelerations: ~1.9 MB); it is
decoded and checked in slices between robot cycles (``TrajectoryGoalDecoder``)."""
CLIENT_TEXT_CHARS = 40
"""Longest piece of a client's text (a field name, a key) echoed in a reply or a log line."""


def encode(message: dict[str, Any]) -> bytes:
    """Encode a message dict, adding the schema version; NaN and infinities become null."""
    body = {"v": SCHEMA_VERSION, **message}
    try:
        return json.dumps(body, separators=(",", ":"), allow_nan=False).encode()
    except ValueError:  # a non-finite float somewhere: JSON has no such numbers
        return json.dumps(_finite_or_null(body), separators=(",", ":"), allow_nan=False).encode()


def message_body(message: object, renamed: Mapping[str, str] | None = None) -> dict[str, Any]:
    """A message type (a dataclass of model.py or publish/: what a decoder returns or a client's
    request) as the fields a client sends: tuples as lists, a None field left out (the daemon's
    default), a field whose name on the wire differs as ``renamed`` says."""
    body: dict[str, Any] = {}
    for item in dataclasses.fields(message):  # type: ignore[arg-type]
        value = getattr(message, item.name)
        if value is not None:
            name = item.name if renamed is None else renamed.get(item.name, item.name)
            body[name] = list(value) if isinstance(value, tuple) else value
    return body


def _finite_or_null(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite_or_null(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite_or_null(v) for v in value]
    return value


def client_text(text: str, limit: int = CLIENT_TEXT_CHARS) -> str:
    """A client's text made safe to echo: control characters escaped, at most ``limit`` characters
    (then ``…``), so no client can make a reply or a log line long or forge a line of its own."""
    short = text[: limit + 1]
    safe = "".join(c if c.isprintable() else repr(c)[1:-1] for c in short)
    return safe[:limit] + "…" if len(safe) > limit else safe


class DuplicateField(ValueError):
    """A JSON object of a client's message names a field twice (``name``)."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.name = name


def _unique_fields(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object's fields as a dict; ``DuplicateField`` if one is named twice (JSON leaves it open,
    and Python's last-one-wins would let ``{"fraction": 0.5, "fraction": 0.2}`` mean 0.2)."""
    data = dict(pairs)
    if len(data) != len(pairs):
        seen: set[str] = set()
        for name, _ in pairs:
            if name in seen:
                raise DuplicateField(name)
            seen.add(name)
    return data


JSON_DECODER = json.JSONDecoder(object_pairs_hook=_unique_fields)
"""The decoder of every client message: any object that names a field twice is refused."""


def duplicate_field(what: str, err: DuplicateField) -> MessageError:
    """The refusal of a message whose object names a field twice, naming the field."""
    return MessageError(f"{what}: the field {client_text(err.name)!r} is given twice; give each field once")


def decode_message(
    payload: bytes | bytearray | memoryview | None, what: str, *, max_bytes: int = SMALL_MESSAGE_BYTES
) -> dict[str, Any]:
    """Parse a client message into a dict, checking size (before decoding), JSON syntax (no field
    named twice in any object), object shape and version."""
    if payload is None or len(payload) == 0:
        raise MessageError(f"{what}: empty message; expected a JSON object")
    if len(payload) > max_bytes:
        raise MessageError(f"{what}: message of {len(payload)} bytes exceeds the limit of {max_bytes} bytes")
    try:
        data = json.loads(bytes(payload), object_pairs_hook=_unique_fields)
    except DuplicateField as err:
        raise duplicate_field(what, err) from None
    except (ValueError, RecursionError) as err:  # JSONDecodeError, UnicodeDecodeError, huge integers
        raise MessageError(f"{what}: not valid JSON: {client_text(str(err), 120)}") from err
    if not isinstance(data, dict):
        raise MessageError(f"{what}: expected a JSON object, got {type(data).__name__}")
    check_version(data, what)
    return data


def check_version(data: dict[str, Any], what: str) -> None:
    """Refuse a message whose ``v`` is not ``SCHEMA_VERSION`` (left out: it is)."""
    version = data.get("v", SCHEMA_VERSION)
    if isinstance(version, bool) or version != SCHEMA_VERSION:
        shown = client_text(repr(version))
        raise MessageError(f"{what}: unsupported schema version {shown}; this daemon speaks {SCHEMA_VERSION}")


def state_time(state: RobotState, now_ns: int) -> dict[str, Any]:
    """The time fields of a message about ``state``: when it arrived on the host (``host_time_ns``, Unix
    ns) and the robot's clock then (``controller_time``, s). Before any state arrived there is no robot
    clock to tell: ``host_time_ns`` is ``now_ns`` (the caller's clock; this module reads none) and
    ``controller_time`` null (docs/keys.md, "Time fields")."""
    if state.host_time_ns > 0:
        return {"host_time_ns": state.host_time_ns, "controller_time": state.controller_time}
    return {"host_time_ns": now_ns, "controller_time": None}


def encode_feedback(robot: str, feedback: GoalFeedback, stamp: dict[str, Any]) -> bytes:
    """Encode goal feedback with its time fields ``stamp`` (``state_time`` of the cycle it reports)."""
    return encode(
        {
            "robot": robot,
            **stamp,
            "goal_id": feedback.goal_id,
            "time_from_start": feedback.time_from_start,
            "duration": feedback.duration,
            "progress": feedback.progress,
            "desired": list(feedback.desired),
            "actual": list(feedback.actual),
            "error": list(feedback.error),
        }
    )


def encode_result(robot: str, result: GoalResult, stamp: dict[str, Any]) -> bytes:
    """Encode a goal result with its time fields ``stamp`` (``state_time`` of the newest state when the
    goal ended)."""
    return encode(
        {
            "robot": robot,
            **stamp,
            "goal_id": result.goal_id,
            "status": result.status.value,
            "reason": result.reason,
            "final_positions": list(result.final_positions),
            "final_error": list(result.final_error),
            "duration": result.duration,
        }
    )
