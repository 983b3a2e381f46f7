"""The decoders of the streaming commands (``<cell>/<robot>/command/<name>``): joint positions, joint
velocities, a twist, freedrive. Each returns the typed command or raises ``MessageError`` naming the
field; the runtime's commands (runtime/streaming.py) act on them. A client sends the typed commands as
``message_body`` gives them (envelope.py), freedrive's as ``freedrive_body``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from urdaemon.errors import MessageError
from urdaemon.publish import fields
from urdaemon.publish.envelope import decode_message

__all__ = [
    "TWIST_FRAMES",
    "StreamMessage",
    "TwistMessage",
    "decode_freedrive",
    "decode_stream_position",
    "decode_stream_velocity",
    "decode_twist",
    "freedrive_body",
]

TWIST_FRAMES = ("base", "tool")
"""The frames a twist may be given in; ``base`` by default."""


@dataclass(frozen=True, slots=True)
class TwistMessage:
    """A decoded twist command: the TCP point's velocity (m/s) and angular velocity (rad/s)."""

    linear: tuple[float, float, float]
    angular: tuple[float, float, float]
    frame: str


@dataclass(frozen=True, slots=True)
class StreamMessage:
    """A decoded streaming command."""

    joint_names: tuple[str, ...] | None
    positions: tuple[float, ...] | None
    velocities: tuple[float, ...] | None


def decode_stream_position(payload: bytes | None) -> StreamMessage:
    """Decode a streaming joint position command: positions, velocities?, joint_names?."""
    what = "joint_position command"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"joint_names", "positions", "velocities"})
    if "positions" not in data:
        raise MessageError(f"{what}.positions: missing")
    velocities = data.get("velocities")
    return StreamMessage(
        joint_names=fields.joint_names(data.get("joint_names"), f"{what}.joint_names"),
        positions=fields.numbers(data["positions"], f"{what}.positions"),
        velocities=None if velocities is None else fields.numbers(velocities, f"{what}.velocities"),
    )


def decode_stream_velocity(payload: bytes | None) -> StreamMessage:
    """Decode a streaming joint velocity command: velocities, joint_names?."""
    what = "joint_velocity command"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"joint_names", "velocities"})
    if "velocities" not in data:
        raise MessageError(f"{what}.velocities: missing")
    return StreamMessage(
        joint_names=fields.joint_names(data.get("joint_names"), f"{what}.joint_names"),
        positions=None,
        velocities=fields.numbers(data["velocities"], f"{what}.velocities"),
    )


def decode_twist(payload: bytes | None) -> TwistMessage:
    """Decode a twist command: linear [3] (m/s), angular [3] (rad/s), frame? (base | tool)."""
    what = "twist command"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"linear", "angular", "frame"})
    vectors = []
    for key in ("linear", "angular"):
        if key not in data:
            raise MessageError(f"{what}.{key}: missing")
        values = fields.numbers(data[key], f"{what}.{key}", max_len=3)
        if len(values) != 3 or not all(math.isfinite(v) for v in values):
            raise MessageError(f"{what}.{key}: expected three finite numbers")
        vectors.append((values[0], values[1], values[2]))
    return TwistMessage(vectors[0], vectors[1], fields.choice(data, "frame", what, TWIST_FRAMES))


def decode_freedrive(payload: bytes | None) -> bool:
    """Decode a freedrive command: active (true keeps freedrive on for one deadman period, false ends it)."""
    what = "freedrive command"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"active"})
    return fields.boolean(data, "active", what, default=True)


def freedrive_body(active: bool) -> dict[str, Any]:
    """A freedrive command's fields (``decode_freedrive``'s inverse)."""
    return {"active": active}
