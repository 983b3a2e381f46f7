"""A sample as the daemon published it → the Foxglove messages it becomes: (topic, bytes, log time).
Every kind converts with the recorder's table (``recording/channels.py``); tf, like the recorder's
file, as one transform per URDF joint (``channels.tf_record``). Pure: runs on the bridge's converter
thread.
"""

from __future__ import annotations

import json
from collections.abc import Sequence

from urdaemon.recording import cdr
from urdaemon.recording.channels import kind_of, record_bytes, time_of

__all__ = ["Record", "description_record", "records_of"]

Record = tuple[str, bytes, int]
"""(topic, the message's bytes, its log time in ns)."""


def records_of(key: str, payload: bytes, received_ns: int, joints: Sequence[tuple[str, str]]) -> list[Record]:
    """The messages the sample of ``key`` becomes (none for a key the recorder does not keep). Raises
    ``ValueError`` (or ``KeyError``, ``TypeError``) for a payload that is not the daemon's message."""
    where = kind_of(key)
    if where is None:
        return []
    message = json.loads(payload)
    if not isinstance(message, dict):
        raise ValueError(f"{key}: the message is not a JSON object")
    return [
        (where.topic, record_bytes(where.kind, message, payload, key, joints), time_of(message, received_ns))
    ]


def description_record(topic: str, urdf: str, now_ns: int) -> Record:
    """The URDF as the recorder stores it: one ``std_msgs/msg/String``."""
    return (topic, cdr.encode_string(urdf), now_ns)
