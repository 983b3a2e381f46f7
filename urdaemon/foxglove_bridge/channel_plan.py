"""Which channels a cell gets over Foxglove, and the Zenoh key expression behind each: the recorder's
table (``recording/channels.py``) read for the cell's robots, so both serve the same topics and
schemas. Pure: no Zenoh, no Foxglove.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from urdaemon.recording.channels import (
    DESCRIPTION_TOPIC,
    ROBOT_DESCRIPTION,
    Kind,
    Schema,
    kind_of,
    recorded_keys,
)

__all__ = ["ChannelPlan", "channel_plan"]

_ANY_ROBOT = "*"
_ANY_GOAL = "0"
"""A goal id put in a key expression's remaining ``*`` to ask ``kind_of`` for its topic."""


@dataclass(frozen=True, slots=True)
class ChannelPlan:
    """One Foxglove channel: its topic and schema, the Zenoh key expression it follows (None for the
    URDF, which is asked for once) and the kind that converts its messages."""

    topic: str
    schema: Schema
    message_encoding: str
    key_expr: str | None
    kind: Kind | None


def channel_plan(cell: str, robots: Sequence[str]) -> list[ChannelPlan]:
    """Every channel of ``cell`` with ``robots``: each recorded key expression, made concrete per robot
    where it names any robot, then the URDF's channel. A key expression ``kind_of`` does not sort is
    left out (the table and this plan then disagree: a bug, which the tests catch)."""
    plans: list[ChannelPlan] = []
    seen: set[str] = set()
    for pattern in recorded_keys(cell):
        parts = pattern.split("/")
        per_robot = len(parts) > 1 and parts[1] == _ANY_ROBOT
        exprs = [pattern.replace(_ANY_ROBOT, robot, 1) for robot in robots] if per_robot else [pattern]
        for expr in exprs:
            where = kind_of(expr.replace(_ANY_ROBOT, _ANY_GOAL))
            if where is None or where.topic in seen:
                continue
            seen.add(where.topic)
            kind = where.kind
            plans.append(ChannelPlan(where.topic, kind.schema, kind.message_encoding, expr, kind))
    plans.append(ChannelPlan(DESCRIPTION_TOPIC, ROBOT_DESCRIPTION, "cdr", None, None))
    return plans
