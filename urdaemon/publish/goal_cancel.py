"""A goal's cancel request: a robot's (``<cell>/<robot>/goal/cancel``, the goal id optional) and a
cell's (``<cell>/goal/cancel``, the goal id required); their decoders and, the client's side, the
request's body (``cancel_body``)."""

from __future__ import annotations

from typing import Any

from urdaemon.errors import MessageError
from urdaemon.publish import fields
from urdaemon.publish.envelope import client_text, decode_message

__all__ = ["cancel_body", "decode_cancel", "decode_cell_cancel"]


def cancel_body(goal_id: str | None) -> dict[str, Any]:
    """The cancel request of goal ``goal_id`` (None: the robot's active goal), ``decode_cancel``'s
    inverse (and ``decode_cell_cancel``'s, given an id)."""
    return {} if goal_id is None else {"goal_id": goal_id}


def decode_cancel(payload: bytes | None) -> str | None:
    """Decode a cancel request: the goal id, or None (or an empty payload) for the active goal."""
    if payload is None or len(payload) == 0:
        return None
    what = "cancel"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"goal_id"})
    goal_id = data.get("goal_id")
    if goal_id is not None and not isinstance(goal_id, str):
        raise MessageError(f"{what}.goal_id: expected a string")
    if goal_id is not None and (len(goal_id) > 200 or not goal_id.isprintable()):
        raise MessageError(f"{what}.goal_id: {client_text(goal_id)!r} is not a goal id")
    return goal_id


def decode_cell_cancel(payload: bytes | None) -> str:
    """Decode a cell goal's cancel: ``{"goal_id": G}`` (the id is required)."""
    goal_id = decode_cancel(payload)
    if goal_id is None:
        raise MessageError("cell cancel.goal_id: required (the cell goal's id)")
    return goal_id
